"""The white-light texture frame: what the projector shows so that the camera sees the object's own colour.

Its tag is one past the pattern set's images (`texture_index`): the capture loop shows it at the ticks it chooses
(every N frames, or on demand), the frame checker passes it on without pairing it, a dump declares the tag
(`texture_pattern`, core/dump.py), and the decoders colour the clouds that follow it with it.
"""

from __future__ import annotations

import numpy as np

from core.patterns import PatternSet


def texture_index(patterns: PatternSet) -> int:
    """The projector image index (and frame tag) of the texture frame: one past the patterns."""
    return len(patterns)


def texture_image(patterns: PatternSet) -> np.ndarray:
    """Full white at the patterns' top level, the projector's size: RGB uint8 (H, W, 3)."""
    w, h = patterns.size
    level = int(patterns.params.get("max_value", 255))
    return np.full((h, w, 3), level, np.uint8)


def with_texture(patterns: PatternSet) -> list[np.ndarray]:
    """The images a projector loads: the patterns, then the texture frame at texture_index."""
    return [*patterns.images, texture_image(patterns)]
