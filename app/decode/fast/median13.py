"""The median of up to 13 values by a sorting network: branch-free and in registers.

The sign model of a raw mosaic's lacking channel (lacking.py) takes each run's local stripe width as the median
of the lengths per stripe of the runs around it. A loop that sorts would branch on every comparison of values in
no order; a network of compare-exchanges (min and max) has no branch, and LLVM keeps its 13 values in registers.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(inline="always")
def _cas(a, b):
    return min(a, b), max(a, b)


@njit(inline="always")
def median13(v: np.ndarray, lo: int, hi: int) -> float:
    """The median of v[lo:hi], hi - lo <= 13 (the mean of the middle two for an even count): the window padded
    with +inf to 13 values and sorted by a network of 48 compare-exchanges (Batcher's odd-even merge sort of 16,
    less the comparators with the padding's last three, which never move), branch-free and in registers."""
    m = hi - lo
    last = v.shape[0] - 1
    v0, v1, v2, v3 = _pad(v, lo, m, 0, last), _pad(v, lo, m, 1, last), _pad(v, lo, m, 2, last), _pad(v, lo, m, 3, last)
    v4, v5, v6, v7 = _pad(v, lo, m, 4, last), _pad(v, lo, m, 5, last), _pad(v, lo, m, 6, last), _pad(v, lo, m, 7, last)
    v8, v9, v10 = _pad(v, lo, m, 8, last), _pad(v, lo, m, 9, last), _pad(v, lo, m, 10, last)
    v11, v12 = _pad(v, lo, m, 11, last), _pad(v, lo, m, 12, last)
    v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12 = network13(
        v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12
    )
    k = m // 2
    upper = _pick(k, v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12)
    lower = _pick(k - 1, v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12)
    return upper if m & 1 else 0.5 * (lower + upper)


@njit(inline="always")
def network13(v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12):
    """The 13 values in increasing order: a network of 48 compare-exchanges (Batcher's odd-even merge sort of
    16, less the comparators with the last three, which a padding of +inf never moves), branch-free and in
    registers."""
    (v0, v1), (v2, v3) = _cas(v0, v1), _cas(v2, v3)
    (v0, v2), (v1, v3) = _cas(v0, v2), _cas(v1, v3)
    (v1, v2), (v4, v5), (v6, v7) = _cas(v1, v2), _cas(v4, v5), _cas(v6, v7)
    (v4, v6), (v5, v7) = _cas(v4, v6), _cas(v5, v7)
    (v5, v6), (v0, v4) = _cas(v5, v6), _cas(v0, v4)
    (v2, v6) = _cas(v2, v6)
    (v2, v4), (v1, v5), (v3, v7) = _cas(v2, v4), _cas(v1, v5), _cas(v3, v7)
    (v3, v5), (v1, v2) = _cas(v3, v5), _cas(v1, v2)
    (v3, v4), (v5, v6), (v8, v9), (v10, v11) = _cas(v3, v4), _cas(v5, v6), _cas(v8, v9), _cas(v10, v11)
    (v8, v10), (v9, v11) = _cas(v8, v10), _cas(v9, v11)
    (v9, v10), (v8, v12) = _cas(v9, v10), _cas(v8, v12)
    (v10, v12) = _cas(v10, v12)
    (v9, v10), (v11, v12), (v0, v8) = _cas(v9, v10), _cas(v11, v12), _cas(v0, v8)
    (v4, v12) = _cas(v4, v12)
    (v4, v8), (v2, v10) = _cas(v4, v8), _cas(v2, v10)
    (v6, v10), (v2, v4) = _cas(v6, v10), _cas(v2, v4)
    (v6, v8), (v10, v12), (v1, v9) = _cas(v6, v8), _cas(v10, v12), _cas(v1, v9)
    (v5, v9), (v3, v11) = _cas(v5, v9), _cas(v3, v11)
    (v7, v11), (v3, v5) = _cas(v7, v11), _cas(v3, v5)
    (v7, v9), (v1, v2), (v3, v4), (v5, v6) = _cas(v7, v9), _cas(v1, v2), _cas(v3, v4), _cas(v5, v6)
    (v7, v8), (v9, v10), (v11, v12) = _cas(v7, v8), _cas(v9, v10), _cas(v11, v12)
    return v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12


@njit(inline="always")
def _pad(v, lo, m, j, last):
    """v[lo + j] if j < m, else +inf (the read kept inside v)."""
    return v[min(lo + j, last)] if j < m else np.inf


@njit(inline="always")
def _pick(k, v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12):
    """The k-th of the values (v0 for k < 1), by selects."""
    r = v0
    r = v1 if k == 1 else r
    r = v2 if k == 2 else r
    r = v3 if k == 3 else r
    r = v4 if k == 4 else r
    r = v5 if k == 5 else r
    r = v6 if k == 6 else r
    r = v7 if k == 7 else r
    r = v8 if k == 8 else r
    r = v9 if k == 9 else r
    r = v10 if k == 10 else r
    r = v11 if k == 11 else r
    return v12 if k == 12 else r
