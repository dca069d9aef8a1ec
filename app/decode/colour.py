"""Undoing the camera's colour crosstalk (ARCHITECTURE.md: color_mixing).

`color_mixing` holds the linear camera R, G, B (rows) produced by each projector primary
(columns); only each column's direction matters. We scale every column so its own channel is 1
and invert: unmixed values stay in camera units of that channel, so thresholds keep their
meaning (a grey surface unmixes to itself).
"""

from __future__ import annotations

import numpy as np

from app.patterns import CHANNEL_INDEX


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
