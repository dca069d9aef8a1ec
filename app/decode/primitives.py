"""Gather, append, fill and run-bound primitives of the fast decoder, dispatched by argument types.

Each is a stub with a numba overload: where the arrays suit the vector intrinsics of `app/decode/simd.py`
(C-contiguous, supported dtypes) the overload emits them, else a plain loop with the same result. Table reads at
data-dependent indices go through `gather` into plain rows, so that the loops after them can be vectorised.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit, types
from numba.extending import overload

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.simd import (
    GATHER_LANES,
    LANES,
    append_sparse16,
    append_where16,
    append_where16_takes,
    fill8,
    gather8,
    gather8_takes,
    run_bounds16,
    run_bounds16_takes,
)

JIT = {"nogil": True, "error_model": "numpy", "_nrt": False}


def c_array(t: types.Type) -> bool:
    """Typing-time test of the overloads: a C-contiguous numba array type."""
    return isinstance(t, types.Array) and t.layout == "C"


def fill_eight(arr: np.ndarray, i: int, value: int | float) -> None:
    """arr[i:i + 8] = value, the caller keeping i >= 0 and room (compiled only)."""
    raise NotImplementedError("numba only")


@overload(fill_eight, jit_options=JIT)
def _fill_eight_impl(arr, i, value):
    kind = types.Integer if arr.dtype == types.int64 else types.Float
    if c_array(arr) and arr.ndim == 1 and arr.dtype in (types.int64, types.float32) and isinstance(value, kind):

        def vector(arr, i, value):
            fill8(arr, i, value)

        return vector

    def scalar(arr, i, value):
        for t in range(8):
            arr[i + t] = value

    return scalar


def gather(dst: np.ndarray, table: np.ndarray, idx: np.ndarray, n: int) -> None:
    """dst[i] = table[idx[i]] for i < n (compiled only: eight at a time with simd.gather8 where it takes the
    arrays, else a loop)."""
    raise NotImplementedError("numba only")


@overload(gather, jit_options=JIT)
def _gather_impl(dst, table, idx, n):
    if gather8_takes(dst, table, idx):

        def vector(dst, table, idx, n):
            i0 = 0
            while i0 + GATHER_LANES <= n:
                gather8(dst, table, idx, i0)
                i0 += GATHER_LANES
            for i in range(i0, n):
                dst[i] = table[idx[i]]

        return vector

    def scalar(dst, table, idx, n):
        for i in range(n):
            dst[i] = table[idx[i]]

    return scalar


def run_bounds(code: np.ndarray, rs: np.ndarray, re: np.ndarray, rc: np.ndarray) -> int:
    """The runs of equal code >= 0 along a row of codes (-1: no code): run j covers pixels rs[j] .. re[j] and
    has code rc[j]; returns how many. The arrays need room for 16 values past the last run (compiled only:
    sixteen pixels at a time with simd.run_bounds16 where it takes the arrays, else a loop)."""
    raise NotImplementedError("numba only")


@overload(run_bounds, jit_options=JIT)
def _run_bounds_impl(code, rs, re, rc):
    if run_bounds16_takes(code, rs, re, rc):

        def vector(code, rs, re, rc):
            W = code.shape[0]
            if W < LANES + 2:
                return run_bounds_loop(code, 0, W, rs, re, rc, 0, 0)[0]
            ns, ne = run_bounds_loop(code, 0, 1, rs, re, rc, 0, 0)
            x = 1
            while x + LANES < W:  # the pixel after the block is read
                ns, ne = run_bounds16(code, x, rs, re, rc, ns, ne)
                x += LANES
            ns, ne = run_bounds_loop(code, x, W, rs, re, rc, ns, ne)
            return ns

        return vector

    def scalar(code, rs, re, rc):
        return run_bounds_loop(code, 0, code.shape[0], rs, re, rc, 0, 0)[0]

    return scalar


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def run_bounds_loop(
    code: np.ndarray, x0: int, x1: int, rs: np.ndarray, re: np.ndarray, rc: np.ndarray, ns: int, ne: int
) -> tuple[int, int]:
    """run_bounds over pixels x0 .. x1 - 1, appending at rs/rc[ns:] and re[ne:]; returns the new (ns, ne).
    Appends without a branch: runs change every few pixels, so a branch per change would be unpredictable."""
    W = code.shape[0]
    for x in range(x0, x1):
        c = code[x]
        prev = code[x - 1] if x > 0 else -1
        nxt = code[x + 1] if x + 1 < W else -1
        rs[ns] = x
        rc[ns] = c
        re[ne] = x
        ns += (c >= 0) & (c != prev)
        ne += (c >= 0) & (c != nxt)
    return ns, ne


def append_where(flags: np.ndarray, n: int, out: np.ndarray) -> int:
    """out[:m] = the positions i < n where flags[i] is nonzero; returns m. out needs room for 16 values past m
    (compiled only: sixteen at a time with simd.append_where16 where it takes the arrays, else a loop)."""
    raise NotImplementedError("numba only")


def append_sparse(flags: np.ndarray, n: int, out: np.ndarray) -> int:
    """append_where for flags that are mostly zero (a row's chain ends): the same result; on an AVX2 target a
    block of 16 without a set flag is skipped (simd.append_sparse16)."""
    raise NotImplementedError("numba only")


def _appends_by(block: Callable) -> Callable:
    """The overload of an append over blocks of LANES flags, `block(flags, x, out, m) -> m` (simd.append_where16 or
    append_sparse16), where it takes the arrays; the loop that finishes the row, or does it all, otherwise."""

    def impl(flags, n, out):
        if append_where16_takes(flags, out):

            def vector(flags, n, out):
                m = 0
                x = 0
                while x + LANES <= n:
                    m = block(flags, x, out, m)
                    x += LANES
                for i in range(x, n):
                    out[m] = i
                    m += flags[i] != 0
                return m

            return vector

        def scalar(flags, n, out):
            m = 0
            for i in range(n):
                out[m] = i
                m += flags[i] != 0
            return m

        return scalar

    return impl


overload(append_where, jit_options=JIT)(_appends_by(append_where16))
overload(append_sparse, jit_options=JIT)(_appends_by(append_sparse16))
