"""Undoing the camera's colour crosstalk (the calibration's `color_mixing`, docs/formats.md).

`color_mixing` holds the linear camera R, G, B (rows) produced by each projector primary
(columns); only each column's direction matters. We scale every column so its own channel is 1
and invert: unmixed values stay in camera units of that channel, so thresholds keep their
meaning (a grey surface unmixes to itself).
"""

from __future__ import annotations

import numpy as np

from core.patterns import CHANNEL_INDEX


def unmixing_matrix(color_mixing: np.ndarray | None) -> np.ndarray:
    """3x3 float32 matrix taking linear camera RGB to projector-primary RGB (identity if None)."""
    if color_mixing is None:
        return np.eye(3, dtype=np.float32)
    M = np.asarray(color_mixing, np.float64).reshape(3, 3)
    diag = np.diag(M).copy()
    diag[diag == 0] = 1.0
    return np.linalg.inv(M / diag[None, :]).astype(np.float32)


def channel_rows(unmix: np.ndarray, channels: str) -> np.ndarray:
    """The rows of the unmixing matrix for the pattern channels, in code-bit order (m x 3)."""
    return np.ascontiguousarray(unmix[[CHANNEL_INDEX[c] for c in channels.upper()]], dtype=np.float32)


def camera_gamma_of(calibration: object) -> float:
    """The camera response exponent a calibration carries (extra 'camera_gamma'), else 1 (linear)."""
    extra = getattr(calibration, "extra", None) or {}
    g = extra.get("camera_gamma", 1.0)
    return float(np.asarray(g).ravel()[0])


def linearisation(levels: int, gamma: float = 1.0, response: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lookup tables raw value -> linear light (3, levels) and its slope, in 8-bit units.

    Linear light is scaled to 0..255 and the slope is per 8-bit raw step, so a noise floor given
    in raw 8-bit DN carries over to the linear domain at every level (dark pixels are compressed
    by a gamma-encoding camera, and so is their noise). `response` (levels,) or (3, levels), if
    given, is the measured raw -> linear curve (0..1) and wins over `gamma`.
    """
    x = np.arange(levels, dtype=np.float64) / (levels - 1)
    if response is not None:
        r = np.asarray(response, np.float64)
        r = np.broadcast_to(r.reshape(-1, levels), (3, levels)) if r.size in (levels, 3 * levels) else None
        if r is None:
            raise ValueError(f"camera response must have {levels} or 3x{levels} values")
        lin = 255.0 * r
    else:
        lin = np.broadcast_to(255.0 * x**gamma, (3, levels))
    step = 255.0 / (levels - 1)  # one raw level in 8-bit units
    dlin = np.gradient(lin, axis=1) / step
    return np.ascontiguousarray(lin, np.float32), np.ascontiguousarray(np.maximum(dlin, 0.0), np.float32)
