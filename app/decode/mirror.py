"""Rigs whose projector columns run right to left in the camera image (a ceiling-mounted projector
turned upside down, a projector seen through a mirror, a camera on the projector's other side).

Window identification reads stripes left to right in the order of the projected sequence; on such a
rig it would read every window backwards and find none. The calibration tells which way columns run:
the decoders then decode the mirrored image (each row read right to left) and mirror the result back.
"""

from __future__ import annotations

import numpy as np

from app.decode.stripemap import StripeMap


def columns_run_backwards(column_range: tuple[np.ndarray, np.ndarray] | None) -> bool:
    """True when the projector column allowed at each pixel falls as the camera x grows (median over the image)."""
    if column_range is None:
        return False
    lo, hi = column_range
    if lo.ndim != 2 or lo.shape[1] < 2:
        return False
    step = np.diff(0.5 * (lo + hi), axis=1)
    step = step[np.isfinite(step)]
    return bool(step.size) and float(np.median(step)) < 0


def mirror_range(column_range: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = column_range
    return np.ascontiguousarray(lo[:, ::-1]), np.ascontiguousarray(hi[:, ::-1])


def mirror_image(image: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(image[:, ::-1])


def mirror_back(sm: StripeMap) -> StripeMap:
    """The stripe map of the mirrored image, on the original pixels (projector columns are unchanged)."""
    sm.column = np.ascontiguousarray(sm.column[:, ::-1])
    if sm.has_confidence:  # (else made from the column when read)
        sm.confidence = np.ascontiguousarray(sm.confidence[:, ::-1])
    if sm.chain is not None:
        sm.chain = np.ascontiguousarray(sm.chain[:, ::-1])
    sm.info = {**sm.info, "mirrored": True}
    return sm
