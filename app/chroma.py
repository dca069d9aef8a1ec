"""Cameras whose colour is subsampled across the rows (webcams' YUYV 4:2:2, MJPEG 4:2:0): the stripe width
their chroma can carry, and the operator's warning when the pattern's stripes are narrower.

The stripes are vertical, so their colour changes across a row, where such a camera keeps one chroma sample
per f = 2 pixels. A stripe needs about two chroma samples, 2 f camera pixels; wider stripes gain nothing more
and the decoder covers less of a surface with them (measured on the virtual rig: docs/performance.md).
"""

from __future__ import annotations

import math

from core.calibration import Calibration
from core.chroma import CHROMA

SAMPLES_PER_STRIPE = 2  # chroma samples a stripe needs


def camera_px_per_projector_px(calibration: Calibration) -> float:
    """How many camera pixels one projector column spans, from the focal lengths (camera and projector at
    about the same distance from the scene, as in a structured-light rig)."""
    return float(calibration.camera_matrix[0][0]) / float(calibration.projector_matrix[0][0])


def stripe_width_for(chroma: str | None, calibration: Calibration) -> int:
    """The narrowest stripe width, in projector pixels, whose stripes this camera's colour carries (1 for full
    colour)."""
    if chroma is None:
        return 1
    need_px = SAMPLES_PER_STRIPE * CHROMA[chroma][0]
    return max(1, math.ceil(need_px / camera_px_per_projector_px(calibration) - 1e-6))


def chroma_warning(chroma: str | None, calibration: Calibration, stripe_width: int, camera: str) -> str | None:
    """The operator's one-line warning when stripes of stripe_width are too narrow for this camera's colour,
    with the width to use; None when they are not (or the colour is full)."""
    need = stripe_width_for(chroma, calibration)
    if chroma is None or stripe_width >= need:
        return None
    f = CHROMA[chroma][0]
    px = stripe_width * camera_px_per_projector_px(calibration)
    return (
        f"slscan: warning: {camera} delivers {chroma} colour (one colour sample per {f} pixels across the stripes): "
        f"a stripe of {stripe_width} projector px is ~{px:.1f} camera px, too narrow for it; set "
        f"scheme.stripe_width: {need} (or auto)"
    )
