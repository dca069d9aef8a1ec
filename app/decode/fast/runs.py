"""Runs and links: a row's stripes, and which neighbouring stripes are linked at which sub-pixel edge.

A run is a maximal row segment of one code; two runs are linked when they can be neighbouring stripes (a gap of
at most gap_max pixels, an allowed transition), with the edge at the zero crossing of the edge signal between
them. `pixel_runs` takes the runs of equal code; `event_runs` (two-shot) takes the intervals between the
channels' zero crossings, so that stripes narrower than a pixel are still seen.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import overload

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import EventScratch, LinkScratch, Runs, Transitions
from app.decode.primitives import JIT, append_where, c_array, gather, run_bounds

SLOW_STEPS = 5  # the edge search's intervals without a branch: a gap of up to 2 pixels (LabelParams.gap_max)


@njit(cache=True, nogil=True, error_model="numpy")
def transitions(wts: np.ndarray, link_ok: np.ndarray, n: int) -> Transitions:
    """The transition table of the codes (weights wts (A, A, C), links link_ok (A, A)) and the link pass's rows
    for rows of up to n runs. Built once per frame."""
    A = wts.shape[0]
    C = wts.shape[2]
    ok = np.zeros(A * A, np.bool_)
    ch = np.zeros(A * A, np.int64)
    w = np.zeros(A * A, np.float32)
    more = np.zeros(A * A, np.bool_)
    info = np.zeros(A * A, np.int64)
    for a in range(A):
        for b in range(A):
            t = a * A + b
            cs = 0
            while cs + 1 < C and wts[a, b, cs] == 0:
                cs += 1
            ok[t] = link_ok[a, b]
            ch[t] = cs
            w[t] = wts[a, b, cs]
            for c in range(cs + 1, C):
                if wts[a, b, c] != 0:
                    more[t] = True
            info[t] = np.int64(ok[t]) | (np.int64(more[t]) << 1) | (ch[t] << 2)
    # the two-shot table is a rule on the codes' bits (see _bit_link): the link pass computes it, no lookups
    bits = A == 1 << C
    for a in range(A):
        for b in range(A):
            t = a * A + b
            wb, cb, okb = _bit_link(a, b)
            bits &= (ok[t] == okb) & (ch[t] == cb) & (w[t] == wb) & (not more[t])
    link = LinkScratch(
        np.empty(n, np.int32),
        np.empty(n, np.int32),
        np.empty(n, np.int32),
        np.empty(n, np.int32),
        np.empty(n, np.float32),
        np.empty(n, np.float32),
        np.empty(n, np.float32),
        np.empty(A * A, np.int32),
        np.empty(n, np.int8),
    )
    return Transitions(ok, ch, w, more, info, bits, link)


@njit(cache=True, nogil=True, inline="always")
def _bit_link(a, b):
    """(weight, channel, ok) of the transition from code a to code b when codes are bit patterns, one bit per
    channel, and linked stripes differ in one bit c (two_shot_spec): weight -1 if a has bit c, else +1; for
    other pairs weight 0 and, as transitions finds for an all-zero weight row, the last channel (two channels)."""
    d = a ^ b
    ok = (d != 0) & ((d & (d - 1)) == 0)
    c = (d >> 1) | (d == 0)  # (two channels: d = 1 -> 0, 2 -> 1; 0 and 3 -> 1)
    wt = np.float32(1.0) - np.float32(2.0) * np.float32((a >> c) & 1)
    return (wt if ok else np.float32(0.0)), c, ok


def _link_pass(nr, fr, A, trans, gap_max, runs):
    """runs.link[j] and runs.edge[j] between runs j and j + 1 as if they were adjacent (the zero crossing between
    their facing pixels); lists in runs.slow the linked ones that need the search, returns how many (compiled
    only: for C-contiguous float32 differences the table and pixel values are gathered first, else one loop)."""
    raise NotImplementedError("numba only")


@overload(_link_pass, jit_options=JIT)
def _link_pass_impl(nr, fr, A, trans, gap_max, runs):
    if c_array(fr) and fr.dtype == types.float32:

        def gathered(nr, fr, A, trans, gap_max, runs):
            # the table and pixel values gathered into plain rows, then one loop over them that is vectorised; the
            # same float operations as the loop below
            rs, re, rc, link, edge = runs.start, runs.end, runs.code, runs.link, runs.edge
            ls = trans.link
            W = fr.shape[1]
            n = nr - 1
            # inf[j]: link and more bits, with the channel's row offset in the flat differences in place of the
            # channel (no multiply per run)
            inf = ls.info
            wj = ls.weight
            if trans.bits:  # two-shot codes: weight, channel and link from the codes' bits (see _bit_link)
                # int32 factors, so that the product is int32 too (AVX2 has no 64-bit vector multiply)
                w4 = np.int32(W << 2)
                for j in range(n):
                    wb, cb, okb = _bit_link(rc[j], rc[j + 1])
                    wj[j] = wb
                    inf[j] = np.int32(okb) | np.int32(np.int32(cb) * w4)
            else:
                info = trans.info
                for t in range(info.shape[0]):
                    ls.info_rows[t] = (info[t] & 3) | (((info[t] >> 2) * W) << 2)
                for j in range(n):
                    ls.pair[j] = rc[j] * A + rc[j + 1]
                gather(inf, ls.info_rows, ls.pair, n)
                gather(wj, trans.weight, ls.pair, n)
            a0 = ls.at0
            a1 = ls.at1
            for j in range(n):
                row = inf[j] >> 2
                a0[j] = row + re[j]
                a1[j] = row + rs[j + 1]
            flat = fr.reshape(fr.size)
            f0 = ls.value0
            f1 = ls.value1
            gather(f0, flat, a0, n)
            gather(f1, flat, a1, n)
            flag = ls.flag
            for j in range(n):
                lk = (rs[j + 1] - re[j] - 1 <= gap_max) & ((inf[j] & 1) != 0)
                s0 = 0.0 + wj[j] * f0[j]
                s1 = 0.0 + wj[j] * f1[j]
                edge[j] = re[j] + s0 / (s0 - s1)
                link[j] = lk
                fast = (rs[j + 1] == re[j] + 1) & ((inf[j] & 2) == 0) & (s0 > 0) & (s1 <= 0)
                flag[j] = lk & (not fast)
            return append_where(flag, n, runs.slow)

        return gathered

    def looped(nr, fr, A, trans, gap_max, runs):
        rs, re, rc, link, edge, slow = runs
        t_ok, t_ch, t_w, t_more = trans.ok, trans.channel, trans.weight, trans.more
        n_slow = 0
        for j in range(nr - 1):
            t = rc[j] * A + rc[j + 1]
            lk = (rs[j + 1] - re[j] - 1 <= gap_max) & t_ok[t]
            cs = t_ch[t]
            w = t_w[t]
            s0 = 0.0 + w * fr[cs, re[j]]
            s1 = 0.0 + w * fr[cs, rs[j + 1]]
            edge[j] = re[j] + s0 / (s0 - s1)
            link[j] = lk
            fast = (rs[j + 1] == re[j] + 1) & (not t_more[t]) & (s0 > 0) & (s1 <= 0)
            slow[n_slow] = j
            n_slow += lk & (not fast)
        return n_slow

    return looped


@njit(cache=True, nogil=True, inline="always")
def _edge_search(s, w, xa, xb, mid):
    """pixel_runs' search for one channel's signal w * s: the falling zero crossing in xa .. xb (xb - xa <=
    SLOW_STEPS) closest to mid, else mid; the loop's float operations and first-closest choice, over a fixed
    SLOW_STEPS intervals with selects instead of branches on the signs."""
    best = mid
    bestd = 1e9
    s1 = 0.0 + w * s[xa]
    for step in range(SLOW_STEPS):
        xx = xa + step
        s0 = s1
        s1 = 0.0 + w * s[min(xx + 1, xb)]
        cross = (xx < xb) & (s0 > 0) & (s1 <= 0)
        # (a crossing's s0 - s1 is > 0; other steps divide by 1, not by a possible 0: no 0 / 0 under any error model)
        xz = xx + s0 / ((s0 - s1) if cross else 1.0)
        d = abs(xz - mid)
        better = cross & (d < bestd)
        best = xz if better else best
        bestd = d if better else bestd
    return best


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def pixel_runs(code: np.ndarray, fr: np.ndarray, wts: np.ndarray, trans: Transitions, gap_max: int, runs: Runs) -> int:
    """The runs of equal code along a row (code (W,), differences fr (C, W)) into runs, with the link and
    sub-pixel edge (zero crossing) between neighbours; returns how many. trans: transitions(wts, link_ok, n).
    runs' rows need room for W + 16 values."""
    C = fr.shape[0]
    rs, re, rc, link, edge, slow = runs
    nr = run_bounds(code, rs, re, rc)
    t_ch, t_w, t_more = trans.channel, trans.weight, trans.more
    A = wts.shape[0]
    # every link's edge as if its runs were adjacent (the usual case) without a branch; the rest are searched
    # below. Adjacent runs' pixels all have a sign, so when the edge signal falls from > 0 to <= 0 between
    # them, that is the only zero crossing the search would find.
    n_slow = _link_pass(nr, fr, A, trans, gap_max, runs)
    for i in range(n_slow):
        j = slow[i]
        t = rc[j] * A + rc[j + 1]
        cs = t_ch[t]
        w = t_w[t]
        xa = re[j] - 1 if re[j] - 1 >= rs[j] else re[j]
        xb = rs[j + 1] + 1 if rs[j + 1] + 1 <= re[j + 1] else rs[j + 1]
        mid = 0.5 * (re[j] + rs[j + 1])
        # two-shot: linked stripes differ in one channel (link_ok), so the edge signal is that channel's d,
        # signed; one-shot: the difference of the two stripes' colours
        if not t_more[t] and xb - xa <= SLOW_STEPS:
            edge[j] = _edge_search(fr[cs], w, xa, xb, mid)
            continue
        best = mid
        bestd = 1e9
        a = rc[j]
        b = rc[j + 1]
        s1 = 0.0 + w * fr[cs, xa]
        if t_more[t]:
            for c in range(cs + 1, C):
                s1 += wts[a, b, c] * fr[c, xa]
        for xx in range(xa, xb):
            s0 = s1
            s1 = 0.0 + w * fr[cs, xx + 1]
            if t_more[t]:
                for c in range(cs + 1, C):
                    s1 += wts[a, b, c] * fr[c, xx + 1]
            if s0 > 0 and s1 <= 0:
                xz = xx + s0 / (s0 - s1)
                if abs(xz - mid) < bestd:
                    bestd = abs(xz - mid)
                    best = xz
        edge[j] = best
    if nr > 0:
        link[nr - 1] = False
    return nr


@njit(cache=True, nogil=True, error_model="numpy")
def event_scratch(m: int, n: int) -> EventScratch:
    """The zero-crossing segmentation's buffers for m channels and up to n events per channel."""
    return EventScratch(
        np.empty((m, n), np.float64),
        np.empty((m, n), np.int64),
        np.empty((m, n), np.int64),
        np.zeros(m, np.int64),
        np.zeros((2, m), np.int64),
        np.zeros(n, np.float64),
        np.zeros(n, np.float64),
    )


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _sign_events(fr, tr, c, gap_max, ex, es, et):
    """Events of channel c along a row (differences fr (C, W), sign thresholds tr (C, W)): 0 = becomes
    known (sign es), 1 = sign change, 2 = unknown."""
    W = fr.shape[1]
    n = 0
    last_x = -1
    last_s = 0
    last_d = 0.0
    for x in range(W):
        d = fr[c, x]
        thr = tr[c, x]
        s = 1 if d >= thr else (-1 if d <= -thr else 0)
        if s == 0:
            continue
        if last_s == 0:
            ex[n] = x - 0.5
            es[n] = s
            et[n] = 0
            n += 1
        elif x - last_x - 1 > gap_max:
            ex[n] = last_x + 0.5
            es[n] = 0
            et[n] = 2
            n += 1
            ex[n] = x - 0.5
            es[n] = s
            et[n] = 0
            n += 1
        elif s != last_s:
            # the raw sign change between the two signed pixels, interpolated between neighbours
            xz = last_x + last_d / (last_d - d) * (x - last_x)
            for xx in range(last_x, x):
                d0 = fr[c, xx]
                d1 = fr[c, xx + 1]
                if (d0 > 0) != (d1 > 0):
                    xz = xx + d0 / (d0 - d1)
                    break
            ex[n] = xz
            es[n] = s
            et[n] = 1
            n += 1
        last_x = x
        last_s = s
        last_d = d
    if last_s != 0:
        ex[n] = last_x + 0.5
        es[n] = 0
        et[n] = 2
        n += 1
    return n


@njit(cache=True, nogil=True, inline="always")
def _close_runs(nr, left, right, rs, re, link):
    """The event runs' whole pixels from their sub-pixel bounds; the last run links to nothing. Returns nr."""
    for j in range(nr):
        rs[j] = int(np.ceil(left[j]))
        re[j] = int(np.floor(right[j]))
    if nr > 0:
        link[nr - 1] = False
    return nr


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _event_runs2(ev, n0, n1, runs):
    """event_runs' merge of the channels' events, written out for two channels with the state in locals.
    Ties go to channel 0, as there."""
    ex, es, et, left, right = ev.x, ev.sign, ev.kind, ev.left, ev.right
    rs, re, rc, link, edge, _ = runs
    p0 = 0
    p1 = 0
    s0 = 0
    s1 = 0
    nr = 0
    active = False
    while p0 < n0 or p1 < n1:
        if p1 >= n1 or (p0 < n0 and ex[0, p0] <= ex[1, p1]):
            bx = ex[0, p0]
            s0 = es[0, p0]
            kind = et[0, p0]
            p0 += 1
        else:
            bx = ex[1, p1]
            s1 = es[1, p1]
            kind = et[1, p1]
            p1 += 1
        if active:
            right[nr - 1] = bx
        was = active
        active = s0 != 0 and s1 != 0
        if active:
            left[nr] = bx
            right[nr] = bx
            rc[nr] = (1 if s0 < 0 else 0) | (2 if s1 < 0 else 0)
            if nr > 0:
                link[nr - 1] = was and kind == 1
                if link[nr - 1]:
                    edge[nr - 1] = bx
            nr += 1
    return _close_runs(nr, left, right, rs, re, link)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def event_runs(fr: np.ndarray, tr: np.ndarray, gap_max: int, ev: EventScratch, runs: Runs) -> int:
    """Two-shot stripes of a row from the zero crossings of each channel's difference (fr, tr: (C, W)) into runs;
    returns how many.

    A stripe is the interval between two consecutive sign changes (of any channel) while every
    channel has a sign, so a stripe narrower than a camera pixel is still seen as long as the
    crossings around it are.
    """
    ex, es, et, cnt = ev.x, ev.sign, ev.kind, ev.count
    rs, re, rc, link, edge, _ = runs
    left, right = ev.left, ev.right
    m = fr.shape[0]
    for c in range(m):
        cnt[c] = _sign_events(fr, tr, c, gap_max, ex[c], es[c], et[c])
    if m == 2:
        return _event_runs2(ev, cnt[0], cnt[1], runs)
    ptr = ev.merge[0]
    sign = ev.merge[1]
    for c in range(m):
        ptr[c] = 0
        sign[c] = 0
    nr = 0
    active = False
    while True:
        best = -1
        bx = 1e18
        for c in range(m):
            if ptr[c] < cnt[c] and ex[c, ptr[c]] < bx:
                bx = ex[c, ptr[c]]
                best = c
        if best < 0:
            break
        i = ptr[best]
        ptr[best] += 1
        if active:
            right[nr - 1] = bx
        was = active
        sign[best] = es[best, i]
        active = True
        for c in range(m):
            if sign[c] == 0:
                active = False
        if active:
            cd = 0
            for c in range(m):
                if sign[c] < 0:
                    cd |= 1 << c
            left[nr] = bx
            right[nr] = bx
            rc[nr] = cd
            if nr > 0:
                link[nr - 1] = was and et[best, i] == 1
                if link[nr - 1]:
                    edge[nr - 1] = bx
            nr += 1
    return _close_runs(nr, left, right, rs, re, link)
