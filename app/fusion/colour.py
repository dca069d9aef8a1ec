"""The colour of a scan: the one place a frame set becomes the RGB image its model is painted with.

A two-shot pair lights only G and B, each pixel at its maximum in one of the two frames, so the per-channel
maximum of the pair is the scene under full G and B light (R holds the ambient light alone). A texture frame (the
projector's full white: every channel lit) gives the object's own colour, and is taken instead where there is one.
"""

from __future__ import annotations

import numpy as np


def scan_colour(frames: list[np.ndarray], texture: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) uint8 RGB from a frame set's RGB frames (uint8 or uint16), or from the texture frame before it."""
    out = frames[0] if texture is None else texture
    for f in frames[1:] if texture is None else []:
        out = np.maximum(out, f)
    if out.dtype != np.uint8:
        out = (out >> 8).astype(np.uint8)
    return np.ascontiguousarray(out)
