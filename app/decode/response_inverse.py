"""The camera response and its inverse: raw codes to linear light and a linear value back to a code.

The decoder linearises every raw value through the camera response (app/decode/colour.py, `linearisation`: a
table (3, levels) per channel, increasing). A value computed in linear light (an interpolation of light, which
adds linearly) is stored back into a frame as a code: the response's inverse, tabulated at equal steps of the
value's square root and interpolated linearly between them, rounded (half up) and clamped to the codes. Square
root steps, because a gamma-encoding camera's codes grow about as the root of the light (gamma 1.8-2.2): its
inverse is nearly straight there, to a small part of a code down to the darkest codes. A linear response (each
code's value proportional to the code, to float32 precision) is tabulated at equal steps of the value itself, a
power of two apart: its inverse is exact, the code the value rounded.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)

MIN_STEPS = 2048  # at least this many steps per channel from 0 to the largest linear value (or its root)


class ResponseInverse(NamedTuple):
    """lin (3, levels) float32: each channel's linear value of each code (increasing); codes (3 (steps + 2),)
    float32: per channel in turn, the fractional code at the linear value (j / scale) ** 2 of each step j (the
    last two beyond the largest value), or at j / scale for a linear response (root False); scale: steps per unit
    of the linear value's square root, or of the value (float32)."""

    lin: np.ndarray
    codes: np.ndarray
    scale: np.float32
    root: bool


_IDENTITY: dict[int, ResponseInverse] = {}


def response_inverse(lin: np.ndarray) -> ResponseInverse:
    """The inverse of a camera response lin (3, levels), increasing per channel (the decoder's luts)."""
    lin = np.ascontiguousarray(lin, np.float32)
    if lin.ndim != 2 or lin.shape[0] != 3 or lin.shape[1] < 2 or np.any(np.diff(lin, axis=1) < 0):
        raise ValueError(f"a camera response must be (3, levels) and increasing, found {lin.shape}")
    levels = np.arange(lin.shape[1], dtype=np.float64)
    proportional = lin[:, -1:].astype(np.float64) * levels / levels[-1]
    linear = bool(np.all(np.abs(lin - proportional) <= 1e-6 * max(float(lin.max()), 1e-30)))
    top = max(float(lin.max()), 1e-30)
    span = top if linear else np.sqrt(top)
    scale = 2.0 ** np.ceil(np.log2(MIN_STEPS / span))
    steps = int(np.ceil(span * scale))
    at = np.arange(steps + 2, dtype=np.float64) / scale
    at = at if linear else at**2
    codes = np.stack([_inverse(lin[c].astype(np.float64), levels, at) for c in range(3)])
    return ResponseInverse(lin, codes.astype(np.float32).ravel(), np.float32(scale), not linear)


def _inverse(lin_c: np.ndarray, levels: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The fractional code at the linear values `at` of one channel: linear between codes (the first of equal
    linear values), 0 below the first and beyond the last on by its last step (the caller rounds and clamps)."""
    keep = np.concatenate([[True], np.diff(lin_c) > 0])
    x, y = lin_c[keep], levels[keep]
    out = np.interp(at, x, y)
    if len(x) > 1:
        beyond = at > x[-1]
        out[beyond] = y[-1] + (at[beyond] - x[-1]) * (y[-1] - y[-2]) / (x[-1] - x[-2])
    return out


def identity_inverse(dtype: np.dtype) -> ResponseInverse:
    """The inverse of the response of a linear camera (a code's linear value is the code), for uint8 or uint16
    frames; built once per depth."""
    levels = 65536 if np.dtype(dtype) == np.uint16 else 256
    if levels not in _IDENTITY:
        _IDENTITY[levels] = response_inverse(np.tile(np.arange(levels, dtype=np.float32), (3, 1)))
    return _IDENTITY[levels]


@njit(inline="always")
def nearest_code(value, at, codes, scale, root, last, top):
    """The code at linear value `value` of the channel whose inverse starts at `at` in codes (channel c at c
    times its steps + 2), interpolated, rounded half up and clamped to 0..top; as a float (selects, no branch).
    last: float32, the channel's steps (the highest step an interpolation starts from); scale, root:
    ResponseInverse's."""
    zero = np.float32(0.0)
    v = max(value, zero)
    t = min((np.sqrt(v) if root else v) * scale, last)
    j = np.int64(t)
    frac = t - np.float32(j)
    lo = codes[at + j]
    v = lo + frac * (codes[at + j + 1] - lo)
    return min(max(np.floor(v + np.float32(0.5)), zero), np.float32(top))
