"""Two-shot differences: per pixel and pattern channel, the unmixed linear frame2 - frame1 and its noise floor.

Raw values are linearised through the camera response (lin, 3 x levels) and the noise floor carried through its
slope (dlin). The tables are read at data-dependent indices, which numba leaves scalar, so whole groups of 16
pixels are gathered by `simd.differences16` (or `differences16_pairs` from a table over 8-bit value pairs) with
the same float32 operations in the same order as the loop `_row_differences`: the results are bit-identical.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import overload

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.primitives import JIT, c_array
from app.decode.simd import LANES, differences16, differences16_pairs, differences16_takes, prefetch_at

PAIR_ENTRIES = 256 * 256  # a pair table's entries per channel (8-bit frames)


@njit(cache=True, nogil=True, error_model="numpy")
def pack_tables(lin: np.ndarray, dlin: np.ndarray) -> np.ndarray:
    """The linearisation and noise-slope tables (3, levels) float32 as one int64 table whose entry i holds the
    float32 pair (lin, dlin) of flat entry i, so one 8-byte gather reads both; an empty table for tables of
    different shapes. Built once per decoder (TwoShotDecoder.tables); 8-bit frames read pair_tables instead."""
    if lin.shape != dlin.shape:
        return np.empty(0, np.int64)
    C, levels = lin.shape
    pk = np.empty(C * levels, np.int64)
    halves = pk.view(np.float32)  # (each int64 entry is written as its two float32 halves)
    for c in range(C):
        for v in range(levels):
            halves[2 * (c * levels + v)] = lin[c, v]
            halves[2 * (c * levels + v) + 1] = dlin[c, v]
    return pk


@njit(cache=True, nogil=True, error_model="numpy")
def pair_tables(lin: np.ndarray, dlin: np.ndarray) -> np.ndarray:
    """For 8-bit frames (tables (3, 256) float32), the int64 table over value pairs that differences16_pairs
    reads: entry c * PAIR_ENTRIES + 256 a + b holds the float32 pair (lin[c, b] - lin[c, a], dlin[c, b] +
    dlin[c, a]), one table of PAIR_ENTRIES for all three channels when their tables are equal, else three; an
    empty table for other tables. Built once per decoder (TwoShotDecoder.tables)."""
    if lin.shape != (3, 256) or dlin.shape != (3, 256):
        return np.empty(0, np.int64)
    # shared when the channels' tables are equal bit for bit (== would take -0.0 for 0.0)
    li = lin.view(np.int32)
    di = dlin.view(np.int32)
    shared = True
    for c in range(1, 3):
        for v in range(256):
            shared &= (li[c, v] == li[0, v]) & (di[c, v] == di[0, v])
    C = 1 if shared else 3
    pk = np.empty(C * PAIR_ENTRIES, np.int64)
    halves = pk.view(np.float32)
    for c in range(C):
        for a in range(256):
            for b in range(256):
                i = c * PAIR_ENTRIES + 256 * a + b
                halves[2 * i] = lin[c, b] - lin[c, a]
                halves[2 * i + 1] = dlin[c, b] + dlin[c, a]
    return pk


def differences(
    f1: np.ndarray,
    f2: np.ndarray,
    y: int,
    lin: np.ndarray,
    dlin: np.ndarray,
    pk: np.ndarray,
    unmix: np.ndarray,
    ta: np.float32,
    out: np.ndarray,
    ahead: tuple,
) -> None:
    """Row y's unmixed differences and noise floors (ta times the noise slopes' weighted sum) of the two pattern
    channels into out[0:4] (compiled only: the gathers of simd.differences16 for C-contiguous frames and
    tables, else the loop). pk: pack_tables or pair_tables (or an empty table). ahead: (2-D array, row) pairs
    whose rows the pair tables' loop asks the caches for meanwhile, a line per 16 pixels (no effect on values)."""
    raise NotImplementedError("numba only")


@overload(differences, jit_options=JIT)
def _differences_impl(f1, f2, y, lin, dlin, pk, unmix, ta, out, ahead):
    if f1 == f2 and differences16_takes(f1, lin, dlin, unmix, ta, out) and c_array(pk) and pk.dtype == types.int64:

        def vector(f1, f2, y, lin, dlin, pk, unmix, ta, out, ahead):
            if f1.shape[2] != 3 or lin.shape[0] != 3 or dlin.shape[0] != 3:
                _differences_loop(f1, f2, y, lin, dlin, unmix, ta, out)
                return
            W = f1.shape[1]
            a = f1[y]
            b = f2[y]
            coefs = (unmix[0, 0], unmix[0, 1], unmix[0, 2], unmix[1, 0], unmix[1, 1], unmix[1, 2], ta)
            x = 0
            if pk.shape[0] == lin.size:  # the tables packed in pairs (pack_tables)
                while x + LANES <= W:
                    differences16(a, b, pk, pk, coefs, out, x)
                    x += LANES
            elif lin.shape[1] == 256 and (pk.shape[0] == PAIR_ENTRIES or pk.shape[0] == 3 * PAIR_ENTRIES):
                x = _pair_differences(a, b, pk, coefs, out, ahead)  # (pair_tables)
            if x + LANES <= W:  # the plain tables (a reshape is a runtime call: only where they are read)
                lf = lin.reshape(lin.size)
                df = dlin.reshape(dlin.size)
                while x + LANES <= W:
                    differences16(a, b, lf, df, coefs, out, x)
                    x += LANES
            _row_differences(
                a[x:], b[x:], (lin[0], lin[1], lin[2]), (dlin[0], dlin[1], dlin[2]), coefs,
                (out[0, x:], out[1, x:], out[2, x:], out[3, x:]),
            )  # fmt: skip

        return vector

    def scalar(f1, f2, y, lin, dlin, pk, unmix, ta, out, ahead):
        _differences_loop(f1, f2, y, lin, dlin, unmix, ta, out)

    return scalar


def _pair_differences(a, b, pairs, coefs, out, ahead):
    """differences of the row's whole groups of 16 pixels from a pair table (differences16_pairs) for 8-bit
    frames, with ahead's prefetches; returns the pixels done (0 for other frames: the caller goes on with the
    other tables)."""
    raise NotImplementedError("numba only")


@overload(_pair_differences, jit_options=JIT)
def _pair_differences_impl(a, b, pairs, coefs, out, ahead):
    if a.dtype == types.uint8:

        def eight_bit(a, b, pairs, coefs, out, ahead):
            x = 0
            while x + LANES <= a.shape[0]:
                # prefetches interleaved with the gathers, which leave the memory system idle
                for arr, row in ahead:
                    prefetch_at(arr, row, min(x, arr.shape[1] - 1))
                differences16_pairs(a, b, pairs, coefs, out, x)
                x += LANES
            return x

        return eight_bit

    def other(a, b, pairs, coefs, out, ahead):
        return 0

    return other


@njit(nogil=True, error_model="numpy", _nrt=False)
def _differences_loop(f1, f2, y, lin, dlin, unmix, ta, out):
    coefs = (unmix[0, 0], unmix[0, 1], unmix[0, 2], unmix[1, 0], unmix[1, 1], unmix[1, 2], ta)
    _row_differences(
        f1[y], f2[y], (lin[0], lin[1], lin[2]), (dlin[0], dlin[1], dlin[2]), coefs, (out[0], out[1], out[2], out[3])
    )


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _row_differences(a, b, lin, dlin, coefs, out):
    """Unmixed linear frame2 - frame1 of the two pattern channels, and their noise floors, for one row: a, b the
    frames' rows (W, 3); lin, dlin the channels' table rows; coefs the two unmixing rows and the half noise
    floor; out the rows (difference 0, difference 1, floor 0, floor 1)."""
    l0, l1, l2 = lin
    dl0, dl1, dl2 = dlin
    u00, u01, u02, u10, u11, u12, ta = coefs
    fv0, fv1, nz0, nz1 = out
    w00 = abs(u00)
    w01 = abs(u01)
    w02 = abs(u02)
    w10 = abs(u10)
    w11 = abs(u11)
    w12 = abs(u12)
    for x in range(a.shape[0]):
        a0 = a[x, 0]
        a1 = a[x, 1]
        a2 = a[x, 2]
        b0 = b[x, 0]
        b1 = b[x, 1]
        b2 = b[x, 2]
        e0 = l0[b0] - l0[a0]
        e1 = l1[b1] - l1[a1]
        e2 = l2[b2] - l2[a2]
        n0 = dl0[b0] + dl0[a0]
        n1 = dl1[b1] + dl1[a1]
        n2 = dl2[b2] + dl2[a2]
        fv0[x] = u00 * e0 + u01 * e1 + u02 * e2
        fv1[x] = u10 * e0 + u11 * e1 + u12 * e2
        nz0[x] = ta * (w00 * n0 + w01 * n1 + w02 * n2)
        nz1[x] = ta * (w10 * n0 + w11 * n1 + w12 * n2)
