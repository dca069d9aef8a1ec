"""Window lookup (paper section 3): the sequence position of every k linked runs, and the confirmed labels.

A window is k consecutive linked runs; its key sum_t code[j + t] * A**t gives its start in the stripe sequence
through the window table (-1: not in the sequence). A window is confirmed when an adjacent window continues it
(position + 1); each run takes the label its confirmed windows agree on (-2 where they disagree).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import LabelScratch, LabelSettings, Runs, StripeCode
from app.decode.primitives import gather


@njit(cache=True, nogil=True, inline="always")
def wrap(v: int, period: int) -> int:
    """v mod period for 0 <= v < 2 * period, without a division; of v's type when both are int32 (numba would
    widen the difference to int64)."""
    return type(v)(v - period) if v >= period else v


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def window_positions(
    nr: int, rc: np.ndarray, link: np.ndarray, table: np.ndarray, A: int, k: int, pos: np.ndarray, keys: np.ndarray
) -> None:
    """pos[j] = the sequence position of the window of runs j..j+k-1 (codes rc, links link) through the table,
    -1 where the window is not k linked runs or not in the sequence; keys: scratch for nr values.

    Each window's key and link count come from its own k runs, so no window depends on the one before and the
    loop is vectorised (the usual k = 7 written out; a rolled key would chain the runs through a multiply)."""
    nw = nr - k + 1
    if k == 7 and A & (A - 1) == 0:
        # a power-of-two alphabet (two-shot: 4 codes): the key by shifts, the table read by gathers, then the links
        s = 0
        while (1 << s) < A:
            s += 1
        if s == 2:
            # shifts by constants keep int32 lanes (shifts by a variable amount are widened to int64)
            for j in range(nw):
                key = rc[j] | (rc[j + 1] << 2) | (rc[j + 2] << 4) | (rc[j + 3] << 6) | (rc[j + 4] << 8)
                keys[j] = key | (rc[j + 5] << 10) | (rc[j + 6] << 12)
        else:
            for j in range(nw):
                key = rc[j] | (rc[j + 1] << s) | (rc[j + 2] << 2 * s) | (rc[j + 3] << 3 * s) | (rc[j + 4] << 4 * s)
                keys[j] = key | (rc[j + 5] << 5 * s) | (rc[j + 6] << 6 * s)
        gather(pos, table, keys, nw)
        for j in range(nw):
            # all six links, and-ed as bools (a sum in int64 would halve the lanes)
            linked = link[j] & link[j + 1] & link[j + 2] & link[j + 3] & link[j + 4] & link[j + 5]
            pos[j] = pos[j] if linked else -1
    elif k == 7:
        A2 = A * A
        A3 = A2 * A
        A4 = A3 * A
        A5 = A4 * A
        A6 = A5 * A
        for j in range(nw):
            key = rc[j] + rc[j + 1] * A + rc[j + 2] * A2 + rc[j + 3] * A3 + rc[j + 4] * A4 + rc[j + 5] * A5
            key += rc[j + 6] * A6
            nl = np.int64(link[j]) + link[j + 1] + link[j + 2] + link[j + 3] + link[j + 4] + link[j + 5]
            pos[j] = table[key] if nl == 6 else -1
    else:
        for j in range(nw):
            key = 0
            nl = 0
            for t in range(k - 1, -1, -1):
                key = key * A + rc[j + t]
            for t in range(k - 1):
                nl += link[j + t]
            pos[j] = table[key] if nl == k - 1 else -1
    for j in range(max(nw, 0), nr):
        pos[j] = -1


@njit(cache=True, nogil=True, inline="always")
def _mod(j, per, inv):
    """j mod per for 0 <= j < 2**24 in int32 lanes, the quotient from a float32 product (at most one off) and
    corrected (no vector integer division)."""
    r = np.int32(j - np.int32(np.int32(np.float32(j) * inv) * per))
    r = np.int32(r + per) if r < 0 else r
    return np.int32(r - per) if r >= per else r


@njit(cache=True, nogil=True, inline="always")
def _offset(p, pp, pn, j, per, inv):
    """Window j's offset (p - j) mod per where it is confirmed (pp, pn: the positions of windows j - 1 and j + 1,
    -1 for none), else -1; int32 throughout, eight to a vector (numba widens int32 arithmetic to int64); positions
    are < per."""
    one = np.int32(1)
    after = wrap(np.int32(pp + one), per)
    nxt = wrap(np.int32(p + one), per)
    ok = ((pp >= 0) & (p == after)) | ((p >= 0) & (pn == nxt))
    o = np.int32(p - _mod(j, per, inv))  # in (-period, period)
    o = np.int32(o + per) if o < 0 else o
    return o if ok else np.int32(-1)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def confirmed_labels(nr: int, pos: np.ndarray, lab: np.ndarray, k: int, period: int, cw: np.ndarray) -> None:
    """lab[i] = the label of run i from the confirmed windows over it (a window confirmed by an adjacent one
    that continues it), -1 where none, -2 where they disagree. cw: scratch for nr + k - 1 values (int32).

    For the usual k = 7 (and a period of at least k) in two branch-free vectorised passes. Window j at position
    p gives its run i = j + t the label (p + t) mod period = (o + i) mod period with its offset
    o = (p - j) mod period, so the windows over a run agree exactly when their offsets are equal: the first pass
    stores each confirmed window's offset (-1 if not confirmed), the second takes the least and the greatest of
    the seven over each run. Continuing windows give their shared runs the same labels, so taking every
    confirmed window's labels gives the window loop's."""
    if k == 7 and nr >= 3 and period >= k:
        # cw[j + 6] = window j's offset where it is confirmed, else -1 (and -1 before window 0)
        none = np.int32(-1)
        for j in range(6):
            cw[j] = none
        per = np.int32(period)
        one = np.int32(1)
        inv = np.float32(1.0) / np.float32(period)
        # the first and last windows apart, the others read through views from j - 1, j, j + 1: plain vector
        # loads, no conditional load and no index of unknown sign (numba's negative-index fix), which the
        # vectorised loop turns into masked loads and selects
        cw[6] = _offset(np.int32(pos[0]), none, np.int32(pos[1]), np.int32(0), per, inv)
        before = pos[0:]
        at = pos[1:]
        after = pos[2:]
        cw7 = cw[7:]
        for i in range(nr - 2):
            cw7[i] = _offset(np.int32(at[i]), np.int32(before[i]), np.int32(after[i]), np.int32(i + one), per, inv)
        j = nr - 1
        cw[j + 6] = _offset(np.int32(pos[j]), np.int32(pos[j - 1]), none, np.int32(j), per, inv)
        for i in range(nr):
            # the seven windows i - 6 .. i: the greatest offset, and the least as unsigned (-1 is the
            # greatest unsigned value, so unconfirmed windows drop out of the least)
            a0 = cw[i]
            a1 = cw[i + 1]
            a2 = cw[i + 2]
            a3 = cw[i + 3]
            a4 = cw[i + 4]
            a5 = cw[i + 5]
            a6 = cw[i + 6]
            hi = max(max(max(a0, a1), max(a2, a3)), max(max(a4, a5), a6))
            u0, u1, u2, u3 = np.uint32(a0), np.uint32(a1), np.uint32(a2), np.uint32(a3)
            u4, u5, u6 = np.uint32(a4), np.uint32(a5), np.uint32(a6)
            lo_u = min(min(min(u0, u1), min(u2, u3)), min(min(u4, u5), u6))
            lv = wrap(np.int32(hi + _mod(np.int32(i), per, inv)), per)  # both < period: one wrap
            lv = lv if lo_u == np.uint32(hi) else np.int32(-2)
            lab[i] = lv if hi >= 0 else none
        return
    for i in range(nr):
        lab[i] = -1
    for j in range(nr):
        p = pos[j]
        if p < 0:
            continue
        # a window that continues the previous one confirms it too, and that one already gave runs
        # j..j+k-2 these same labels (or marked them -2): only the last run is new
        follows = j > 0 and pos[j - 1] >= 0 and p == wrap(pos[j - 1] + 1, period)
        conf = follows or (j + 1 < nr and pos[j + 1] >= 0 and pos[j + 1] == wrap(p + 1, period))
        if not conf:
            continue
        for t in range(k - 1 if follows else 0, k):
            i = j + t
            lv = wrap(p + t, period)
            if lab[i] == -1:
                lab[i] = lv
            elif lab[i] != lv:
                lab[i] = -2


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def window_labels(nr: int, runs: Runs, stripes: StripeCode, settings: LabelSettings, scratch: LabelScratch) -> None:
    """scratch.label[:nr] = the confirmed labels of the row's nr runs (see confirmed_labels)."""
    A = stripes.link_ok.shape[0]
    window_positions(nr, runs.code, runs.link, stripes.table, A, settings.k, scratch.pos, scratch.keys)
    confirmed_labels(nr, scratch.pos, scratch.label, settings.k, settings.period, scratch.confirmed)
