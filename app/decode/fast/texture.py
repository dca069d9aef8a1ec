"""The two-shot pair's texture: the average of its two frames."""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def average_frames(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = (a + b) // 2 element by element without overflow, for unsigned integer frames of one shape and
    dtype: (a >> 1) + (b >> 1) + (a & b & 1) in one vectorised pass."""
    fa = a.reshape(a.size)
    fb = b.reshape(b.size)
    fo = out.reshape(out.size)
    one = a.dtype.type(1)
    for i in range(fa.size):
        x = fa[i]
        y = fb[i]
        fo[i] = (x >> one) + (y >> one) + (x & y & one)
