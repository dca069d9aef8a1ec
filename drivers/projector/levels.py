"""Projector output levels: a brightness and gamma lookup table applied to patterns before upload.

Pure numpy. The identity (gamma 1, brightness 1) leaves every value unchanged, so patterns are
projected exactly as synthesised unless the operator asks otherwise.
"""

from __future__ import annotations

import numpy as np

from core.errors import InputError


def levels_lut(gamma: float = 1.0, brightness: float = 1.0) -> np.ndarray:
    """256-entry uint8 table: out = round(255 * brightness * (in / 255) ** (1 / gamma)), clipped.

    gamma > 1 lifts mid-tones (to pre-compensate a projector's display gamma), brightness scales
    the whole range (< 1 dims a projector that saturates the camera).
    """
    if not (isinstance(gamma, int | float) and 0.1 <= gamma <= 10):
        raise InputError(f"projector gamma {gamma!r} is out of range (0.1 to 10)")
    if not (isinstance(brightness, int | float) and 0 <= brightness <= 1):
        raise InputError(f"projector brightness {brightness!r} is out of range (0 to 1)")
    if gamma == 1 and brightness == 1:
        return np.arange(256, dtype=np.uint8)
    x = np.arange(256, dtype=np.float64) / 255.0
    return np.clip(np.rint(255.0 * brightness * x ** (1.0 / gamma)), 0, 255).astype(np.uint8)


def apply_levels(image: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """The image through the table (a new array; the input is not modified)."""
    return lut[image]
