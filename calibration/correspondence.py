"""Projector column and row at every camera pixel of one pose, from its Gray-code frames.

A thin adapter over the project's Gray-code decoder (app/decode/graycode.py): calibration never
decodes Gray code itself.
"""

from __future__ import annotations

import numpy as np


def decode_projector_maps(frames: list[np.ndarray], patterns_meta: dict) -> tuple[np.ndarray, np.ndarray]:
    """(column, row) float arrays (H, W), NaN where the Gray code did not decode."""
    from app.decode import graycode  # lazy: the decoder package pulls in numba kernels

    column = graycode.decode_graycode(frames, patterns_meta, "column")
    row = graycode.decode_graycode(frames, patterns_meta, "row")
    return np.asarray(column, np.float64), np.asarray(row, np.float64)
