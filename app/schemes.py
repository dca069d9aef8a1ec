"""The pattern schemes: what each projects, how its frames make a set, and what decodes a set.

Code that behaves differently by scheme asks its `Scheme` (frames per set, projection order,
pattern options, decoder) instead of comparing scheme names.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.errors import InputError
from core.patterns import PatternSet, graycode_patterns, one_shot_patterns, two_shot_patterns


@dataclass(frozen=True)
class Scheme:
    name: str
    make_patterns: Callable[..., PatternSet]
    pattern_options: tuple[str, ...]  # the pattern function's options that `scheme:` and the CLI may set
    shots: int | None  # frames per set: 1, 2, or None = one frame per pattern (Gray code)
    # consecutive frames show different patterns (the capture loop checks the pixels change)
    alternates: bool
    # a complete set is used once: its frames never start the next set (two-shot pairs slide instead)
    disjoint_sets: bool
    make_decoder: Callable[..., Any]  # (pattern_meta, projector_width, mixing, column_range, segmentation, gamma)
    stripes: Callable[[Any, Sequence[np.ndarray]], Any]  # (decoder, frames in pattern order) -> StripeMap
    depth_in_decode: bool = False  # the decoder can triangulate in its own pass (decode_depth)
    compiled: bool = True  # the decoder runs numba kernels that a warm-up compiles
    segmentation: bool = False  # takes `scheme.segmentation`

    def frames_per_set(self, n_patterns: int) -> int:
        return self.shots if self.shots is not None else n_patterns

    def frame_order(self, n_patterns: int) -> list[int]:
        """Projection order: two-shot alternates 0, 1, 0, 1 (so sliding pairs give a set per frame)."""
        return [0] if self.shots == 1 else list(range(n_patterns))


def _one_shot_decoder(meta: dict, proj_w: int, mixing: Any, column_range: Any, segmentation: Any, gamma: float):
    from app.decode.oneshot import OneShotDecoder

    return OneShotDecoder(meta, proj_w, mixing, column_range, camera_gamma=gamma)


def _two_shot_decoder(meta: dict, proj_w: int, mixing: Any, column_range: Any, segmentation: Any, gamma: float):
    from app.decode.twoshot import TwoShotDecoder, TwoShotParams

    params = TwoShotParams(segmentation=segmentation) if segmentation else None
    return TwoShotDecoder(meta, proj_w, mixing, column_range, params, camera_gamma=gamma)


def _graycode_decoder(meta: dict, proj_w: int, mixing: Any, column_range: Any, segmentation: Any, gamma: float):
    from app.decode.graycode import GrayCodeDecoder

    return GrayCodeDecoder(meta, column_range)


ONE_SHOT = Scheme(
    "one-shot",
    one_shot_patterns,
    ("k", "colors", "stripe_width"),
    shots=1,
    alternates=False,
    disjoint_sets=False,
    make_decoder=_one_shot_decoder,
    stripes=lambda dec, frames: dec.decode(frames[0]),
)
TWO_SHOT = Scheme(
    "two-shot",
    two_shot_patterns,
    ("k", "channels", "stripe_width"),
    shots=2,
    alternates=True,
    disjoint_sets=False,
    make_decoder=_two_shot_decoder,
    stripes=lambda dec, frames: dec.decode(frames[0], frames[1]),
    depth_in_decode=True,
    segmentation=True,
)
GRAYCODE = Scheme(
    "graycode",
    graycode_patterns,
    (),
    shots=None,
    alternates=True,
    disjoint_sets=True,
    make_decoder=_graycode_decoder,
    stripes=lambda dec, frames: dec.decode(list(frames)),
    compiled=False,
)
SCHEMES: dict[str, Scheme] = {s.name: s for s in (ONE_SHOT, TWO_SHOT, GRAYCODE)}


def get_scheme(name: str | Scheme) -> Scheme:
    """The Scheme of a name (one-shot, two-shot, graycode); an unknown name is an InputError."""
    if isinstance(name, Scheme):
        return name
    try:
        return SCHEMES[name]
    except KeyError:
        raise InputError(f"unknown scheme {name!r} (choose one of {', '.join(SCHEMES)})") from None


def pattern_options(scheme: Scheme, values: Any) -> dict:
    """The scheme's pattern options read from `values` (argparse's namespace): {k: ..., channels: ...}."""
    return {key: getattr(values, key) for key in scheme.pattern_options}
