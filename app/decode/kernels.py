"""Compiled (numba) per-pixel and per-row loops of the stripe decoders.

`app/decode/reference.py` implements the same steps in plain numpy; the tests compare both.

Vocabulary: a *code* is a pixel's stripe symbol (0..A-1, -1 = no value); a *run* is a maximal
row segment of one code; two runs are *linked* when they can be neighbouring stripes (small gap,
allowed transition); a *window* is k linked runs, identified through a lookup table; a window is
*confirmed* when an adjacent window agrees with it; a *chain* is a row segment of consecutively
labelled, linked runs, from which the columns are interpolated between sub-pixel stripe edges.

The two-shot path is `twoshot_rows`: one pass per row over the frames into one-row buffers (classify,
runs, labels, the vertical check two rows behind), no full-image codes or differences. Measured
lessons on this machine: a numba helper called per pixel (not per row) cost ~80 ns a call, and
float32 output buffers next to float32 tables make the compiler reload the tables after every store;
keep per-pixel work inline with coefficients in locals. The compiler vectorises a loop only when each
iteration is independent and reads plain rows: no index computed per element (x // block), no value
carried from the iteration before through memory (a counter array incremented per pixel, a segment
index stepped by a load), no table lookups (it emits no gathers here). Such loops ran 3-5x faster.
Table reads at data-dependent indices are therefore done by explicit gathers (`app/decode/simd.py`): the
two-shot differences whole, elsewhere into plain rows that the loop after them reads (`_gather`).

Kernels that allocate nothing are compiled without reference counting (numba's `_nrt=False`): in them every
array view (a row, a slice, a tuple's member) increfs and decrefs its parent through an atomic runtime
call, 15 % of the two-shot decoder's time. Their arrays all belong to the caller for the whole call, and
they return none. Kernels that allocate (`twoshot_rows`, `label_rows`, ...) keep it; numba refuses to
compile an allocation without it.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import overload

import app.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.simd import (
    GATHER_LANES,
    LANES,
    append_where16,
    append_where16_takes,
    differences16,
    differences16_pairs,
    differences16_takes,
    fill8,
    gather8,
    gather8_takes,
    prefetch_at,
    run_bounds16,
    run_bounds16_takes,
    spread8x2,
)
from app.triangulate import moebius_depth_row


def _c_array(t: types.Type) -> bool:
    """Typing-time test of the overloads below: a C-contiguous numba array type."""
    return isinstance(t, types.Array) and t.layout == "C"


# Pixels beyond a chain's outer stripe edges keep a value up to this many stripes out (the end stripe's
# own pixels; its far side is not measured, so beyond half a stripe is the blur of a shadow edge).
END_EXT = 0.5


@njit(cache=True, nogil=True, inline="always")
def _wrap(v, period):
    """v mod period for 0 <= v < 2 * period (Python's % costs a division per call); of v's type when both are
    int32 (numba would widen the difference to int64)."""
    return type(v)(v - period) if v >= period else v


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _block_extrema(feat, y, c, block, nb, bmax, bmin, absolute):
    """Per block of `block` pixels along row y: max and min of feat[y, :, c] (or of |feat|)."""
    W = feat.shape[1]
    for b in range(nb):
        hi = -np.inf
        lo = np.inf
        for x in range(b * block, min(W, (b + 1) * block)):
            v = feat[y, x, c]
            if absolute:
                v = abs(v)
            if v > hi:
                hi = v
            if v < lo:
                lo = v
        bmax[b] = hi
        bmin[b] = lo


@njit(cache=True, nogil=True, error_model="numpy")
def twoshot_classify(f1, f2, lin, dlin, unmix, t_abs, t_rel, t_rel_edge, block, code, feat, noise):
    """code[y, x] = bits (1 = channel max in frame 1, i.e. frame2 - frame1 < 0), -1 when unsure.

    Raw values are linearised through lin (3, L) (the camera response), then feat[y, x, c] =
    unmixed linear frame2 - frame1 of pattern channel c. A sign counts only when |d| is above the
    noise floor (t_abs raw 8-bit DN carried through the response slope dlin: noise[y, x, c]) and
    above t_rel times the channel's local amplitude (max |d| over about 3 blocks), so coloured
    surfaces (small amplitude in one channel) keep their codes while stripe edges (d crossing
    zero) and shadows (no amplitude) give no code.
    """
    H, W = code.shape
    m = unmix.shape[0]
    nb = (W + block - 1) // block
    bmax = np.empty((m, nb), np.float32)
    bmin = np.empty(nb, np.float32)
    for y in range(H):
        for x in range(W):
            a0 = f1[y, x, 0]
            a1 = f1[y, x, 1]
            a2 = f1[y, x, 2]
            b0 = f2[y, x, 0]
            b1 = f2[y, x, 1]
            b2 = f2[y, x, 2]
            d0 = lin[0, b0] - lin[0, a0]
            d1 = lin[1, b1] - lin[1, a1]
            d2 = lin[2, b2] - lin[2, a2]
            n0 = dlin[0, b0] + dlin[0, a0]
            n1 = dlin[1, b1] + dlin[1, a1]
            n2 = dlin[2, b2] + dlin[2, a2]
            for c in range(m):
                u0 = unmix[c, 0]
                u1 = unmix[c, 1]
                u2 = unmix[c, 2]
                feat[y, x, c] = u0 * d0 + u1 * d1 + u2 * d2
                noise[y, x, c] = t_abs * 0.5 * (abs(u0) * n0 + abs(u1) * n1 + abs(u2) * n2)
        for c in range(m):
            _block_extrema(feat, y, c, block, nb, bmax[c], bmin, True)
        for x in range(W):
            b = x // block
            cd = 0
            ok = True
            for c in range(m):
                a = bmax[c, b]
                if b > 0 and bmax[c, b - 1] > a:
                    a = bmax[c, b - 1]
                if b + 1 < nb and bmax[c, b + 1] > a:
                    a = bmax[c, b + 1]
                nz = noise[y, x, c]
                d = feat[y, x, c]
                thr = t_rel * a
                if thr < nz:
                    thr = nz
                if not abs(d) >= thr:  # (a NaN difference has no sign either, as in the numpy reference)
                    ok = False
                elif d < 0:
                    cd |= 1 << c
                te = t_rel_edge * a
                noise[y, x, c] = te if te > nz else nz  # the event mode's threshold
            code[y, x] = cd if ok else -1


@njit(cache=True, nogil=True, error_model="numpy")
def oneshot_classify(img, unmix, colour_rows, t_abs, t_margin, block, use_hue, code, feat):
    """code[y, x] = index of the stripe colour (0..N-1), -1 when unsure.

    feat[y, x, c] = colour c's normalised level in [0, 1]. Local contrast normalisation (default):
    each unmixed primary is rescaled by its own min and max over about 3 blocks of the row, which
    discounts ambient light and surface colour channel by channel. With use_hue the unmixed
    colour is only divided by its brightness (a hue/chromaticity classifier, the paper's choice).
    """
    H, W = code.shape
    n = colour_rows.shape[0]
    nb = (W + block - 1) // block
    bmax = np.empty((3, nb), np.float32)
    bmin = np.empty((3, nb), np.float32)
    u = np.empty((W, 3), np.float32)
    for y in range(H):
        for x in range(W):
            r = np.float32(img[y, x, 0])
            g = np.float32(img[y, x, 1])
            b = np.float32(img[y, x, 2])
            for c in range(3):
                u[x, c] = unmix[c, 0] * r + unmix[c, 1] * g + unmix[c, 2] * b
                feat[y, x, c] = u[x, c]
        if not use_hue:
            for c in range(3):
                _block_extrema(feat, y, c, block, nb, bmax[c], bmin[c], False)
        for x in range(W):
            bk = x // block
            s = np.float32(0.0)
            for c in range(3):
                if use_hue:
                    v = u[x, c]
                    if v < 0:
                        v = 0
                    feat[y, x, c] = v
                    s += v
                else:
                    hi = bmax[c, bk]
                    lo = bmin[c, bk]
                    if bk > 0:
                        hi = max(hi, bmax[c, bk - 1])
                        lo = min(lo, bmin[c, bk - 1])
                    if bk + 1 < nb:
                        hi = max(hi, bmax[c, bk + 1])
                        lo = min(lo, bmin[c, bk + 1])
                    span = hi - lo
                    if span < t_abs:
                        feat[y, x, c] = 0.0
                    else:
                        feat[y, x, c] = (u[x, c] - lo) / span
            if use_hue:
                if s < t_abs:
                    for c in range(3):
                        feat[y, x, c] = 0.0
                else:
                    for c in range(3):
                        feat[y, x, c] /= s
            best = -1
            v1 = np.float32(-1.0)
            v2 = np.float32(-1.0)
            for i in range(n):
                v = feat[y, x, colour_rows[i]]
                if v > v1:
                    v2 = v1
                    v1 = v
                    best = i
                elif v > v2:
                    v2 = v
            code[y, x] = best if (v1 - v2 >= t_margin and v1 > 0) else -1


@njit(cache=True, nogil=True, error_model="numpy")
def _transitions(wts, link_ok, n):
    """Per code transition t = a * A + b: whether it can link two runs, the first channel of its edge signal
    (wts[a, b]), that channel's weight, whether more channels weigh in (one-shot), and the three packed into
    one int64 (ok | more << 1 | channel << 2) for the gathered link pass; then that pass's work rows for rows
    of up to n runs (int32 (5, n), float32 (3, n), int32 (A * A,) and int8 (n,)), and whether the table is
    _bit_link's rule (the pass then computes it). Built once per frame."""
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
    work = (np.empty((5, n), np.int32), np.empty((3, n), np.float32), np.empty(A * A, np.int32), np.empty(n, np.int8))
    return ok, ch, w, more, info, work[0], work[1], work[2], work[3], bits


@njit(cache=True, nogil=True, inline="always")
def _bit_link(a, b):
    """(weight, channel, ok) of the transition from code a to code b when codes are bit patterns, one bit per
    channel, and linked stripes differ in one bit c (two_shot_spec): weight -1 if a has bit c, else +1; for
    other pairs weight 0 and, as _transitions finds for an all-zero weight row, the last channel (two channels)."""
    d = a ^ b
    ok = (d != 0) & ((d & (d - 1)) == 0)
    c = (d >> 1) | (d == 0)  # (two channels: d = 1 -> 0, 2 -> 1; 0 and 3 -> 1)
    wt = np.float32(1.0) - np.float32(2.0) * np.float32((a >> c) & 1)
    return (wt if ok else np.float32(0.0)), c, ok


def _link_pass(nr, fr, A, trans, gap_max, rs, re, rc, link, edge, slow):
    """link[j] and edge[j] between runs j and j + 1 as if they were adjacent (the zero crossing between their
    facing pixels); lists in slow the linked ones that need the search, returns how many (compiled only: the
    overload below gathers the table and pixel values first for C-contiguous differences, else one loop)."""
    raise NotImplementedError("numba only")


@overload(_link_pass, jit_options={"nogil": True, "error_model": "numpy", "_nrt": False})
def _link_pass_impl(nr, fr, A, trans, gap_max, rs, re, rc, link, edge, slow):
    if _c_array(fr) and fr.dtype == types.float32:

        def gathered(nr, fr, A, trans, gap_max, rs, re, rc, link, edge, slow):
            # gathers into work rows, then one loop over plain rows that the compiler vectorises (a table read
            # in the loop keeps it scalar); the same float operations as the loop below
            t_w, info, iw, fw, info_w, flag = trans[2], trans[4], trans[5], trans[6], trans[7], trans[8]
            W = fr.shape[1]
            n = nr - 1
            tt, inf, a0, a1 = iw[0], iw[1], iw[2], iw[3]
            wj, f0, f1 = fw[0], fw[1], fw[2]
            # inf[j]: link and more bits, with the channel's row offset in the flat differences packed in place of
            # the channel (a multiply per run was the loop's costliest instruction)
            if trans[9]:
                # two-shot codes: the transition's weight, channel and link from the codes' bits (see _bit_link;
                # two table gathers per eight runs were a third of the pass)
                for j in range(n):
                    wb, cb, okb = _bit_link(rc[j], rc[j + 1])
                    wj[j] = wb
                    inf[j] = np.int64(okb) | ((cb * W) << 2)
            else:
                for t in range(info.shape[0]):
                    info_w[t] = (info[t] & 3) | (((info[t] >> 2) * W) << 2)
                for j in range(n):
                    tt[j] = rc[j] * A + rc[j + 1]
                _gather(inf, info_w, tt, n)
                _gather(wj, t_w, tt, n)
            for j in range(n):
                row = inf[j] >> 2
                a0[j] = row + re[j]
                a1[j] = row + rs[j + 1]
            flat = fr.reshape(fr.size)
            _gather(f0, flat, a0, n)
            _gather(f1, flat, a1, n)
            for j in range(n):
                lk = (rs[j + 1] - re[j] - 1 <= gap_max) & ((inf[j] & 1) != 0)
                s0 = 0.0 + wj[j] * f0[j]
                s1 = 0.0 + wj[j] * f1[j]
                edge[j] = re[j] + s0 / (s0 - s1)
                link[j] = lk
                fast = (rs[j + 1] == re[j] + 1) & ((inf[j] & 2) == 0) & (s0 > 0) & (s1 <= 0)
                flag[j] = lk & (not fast)
            return _append_where(flag, n, slow)

        return gathered

    def looped(nr, fr, A, trans, gap_max, rs, re, rc, link, edge, slow):
        t_ok, t_ch, t_w, t_more = trans[:4]
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


def _fill8(arr, i, value):
    """arr[i:i + 8] = value, the caller keeping i >= 0 and room (compiled only: one vector store with simd.fill8
    where it takes the array, else a loop)."""
    raise NotImplementedError("numba only")


@overload(_fill8, jit_options={"nogil": True, "error_model": "numpy", "_nrt": False})
def _fill8_impl(arr, i, value):
    kind = types.Integer if arr.dtype == types.int64 else types.Float
    if _c_array(arr) and arr.ndim == 1 and arr.dtype in (types.int64, types.float32) and isinstance(value, kind):

        def vector(arr, i, value):
            fill8(arr, i, value)

        return vector

    def scalar(arr, i, value):
        for t in range(8):
            arr[i + t] = value

    return scalar


def _gather(dst, table, idx, n):
    """dst[i] = table[idx[i]] for i < n (compiled only: eight at a time with simd.gather8 where it takes the
    arrays, else a loop)."""
    raise NotImplementedError("numba only")


@overload(_gather, jit_options={"nogil": True, "error_model": "numpy", "_nrt": False})
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


def _run_bounds(code, rs, re, rc):
    """The runs of equal code >= 0 along a row of codes (-1: no code): run j covers pixels rs[j] .. re[j] and
    has code rc[j]; returns how many (compiled only: sixteen pixels at a time with simd.run_bounds16 where it
    takes the arrays, else a loop)."""
    raise NotImplementedError("numba only")


@overload(_run_bounds, jit_options={"nogil": True, "error_model": "numpy", "_nrt": False})
def _run_bounds_impl(code, rs, re, rc):
    if run_bounds16_takes(code, rs, re, rc):

        def vector(code, rs, re, rc):
            W = code.shape[0]
            if W < LANES + 2:
                return _run_bounds_loop(code, 0, W, rs, re, rc, 0, 0)[0]
            ns, ne = _run_bounds_loop(code, 0, 1, rs, re, rc, 0, 0)
            x = 1
            while x + LANES < W:  # the pixel after the block is read
                ns, ne = run_bounds16(code, x, rs, re, rc, ns, ne)
                x += LANES
            ns, ne = _run_bounds_loop(code, x, W, rs, re, rc, ns, ne)
            return ns

        return vector

    def scalar(code, rs, re, rc):
        return _run_bounds_loop(code, 0, code.shape[0], rs, re, rc, 0, 0)[0]

    return scalar


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _run_bounds_loop(code, x0, x1, rs, re, rc, ns, ne):
    """_run_bounds over pixels x0 .. x1 - 1, appending at rs/rc[ns:] and re[ne:]; returns the new (ns, ne).
    Appends without a branch (runs change every ~2 px: a branch per change is mispredicted half the time)."""
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


def _append_where(flags, n, out):
    """out[:m] = the positions i < n where flags[i] is nonzero; returns m (compiled only: sixteen at a time with
    simd.append_where16 where it takes the arrays, else a loop)."""
    raise NotImplementedError("numba only")


@overload(_append_where, jit_options={"nogil": True, "error_model": "numpy", "_nrt": False})
def _append_where_impl(flags, n, out):
    if append_where16_takes(flags, out):

        def vector(flags, n, out):
            m = 0
            x = 0
            while x + LANES <= n:
                m = append_where16(flags, x, out, m)
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


SLOW_STEPS = 5  # the edge search's intervals without a branch: a gap of up to 2 pixels (LabelParams.gap_max)


@njit(cache=True, nogil=True, inline="always")
def _edge_search(s, w, xa, xb, mid):
    """_pixel_runs' search for one channel's signal w * s: the falling zero crossing in xa .. xb (xb - xa <=
    SLOW_STEPS) closest to mid, else mid; the same float operations and the same first-closest choice as the
    loop, over a fixed SLOW_STEPS intervals with selects (the loop's branches on the signs, one link in ten at
    1280 x 1024, were mispredicted)."""
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
def _pixel_runs(code, fr, wts, trans, gap_max, rs, re, rc, link, edge):
    """Runs of equal code along a row (code (W,), differences fr (C, W)); link and sub-pixel edge (zero
    crossing) between neighbours. trans: _transitions(wts, link_ok, n). rs, re, rc need room for W + 16 values
    and rc for 2 W + 17 (the runs to search are listed after its first W + 1, sixteen at a time)."""
    W = code.shape[0]
    C = fr.shape[0]
    nr = _run_bounds(code, rs, re, rc)
    t_ch, t_w, t_more = trans[1:4]
    A = wts.shape[0]
    # every link's edge as if its runs were adjacent (the usual case) without a branch; the rest are searched
    # below. Adjacent runs' pixels all have a sign, so when the edge signal falls from > 0 to <= 0 between
    # them, that is the only zero crossing the search would find. (rc's tail holds the runs to search.)
    slow = rc[W + 1 :]
    n_slow = _link_pass(nr, fr, A, trans, gap_max, rs, re, rc, link, edge, slow)
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


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _event_runs2(ex, es, et, n0, n1, rs, re, rc, link, edge, left, right):
    """_event_runs' merge of the channels' events, written out for two channels with the state in locals
    (the general loop over channels cost more than finding the events). Ties go to channel 0, as there."""
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
    for j in range(nr):
        rs[j] = int(np.ceil(left[j]))
        re[j] = int(np.floor(right[j]))
    if nr > 0:
        link[nr - 1] = False
    return nr


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _event_runs(fr, tr, gap_max, ex, es, et, cnt, ps, rs, re, rc, link, edge, left, right):
    """Two-shot stripes of a row from the zero crossings of each channel's difference (fr, tr: (C, W)).

    A stripe is the interval between two consecutive sign changes (of any channel) while every
    channel has a sign, so a stripe narrower than a camera pixel is still seen as long as the
    crossings around it are. cnt (C,) and ps (2, C) int64 are scratch.
    """
    m = fr.shape[0]
    for c in range(m):
        cnt[c] = _sign_events(fr, tr, c, gap_max, ex[c], es[c], et[c])
    if m == 2:
        return _event_runs2(ex, es, et, cnt[0], cnt[1], rs, re, rc, link, edge, left, right)
    ptr = ps[0]
    sign = ps[1]
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
    for j in range(nr):
        rs[j] = int(np.ceil(left[j]))
        re[j] = int(np.floor(right[j]))
    if nr > 0:
        link[nr - 1] = False
    return nr


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _window_positions(nr, rc, link, table, A, k, pos, keys):
    """pos[j] = the sequence position of the window of runs j..j+k-1 (its key sum_t rc[j + t] * A**t through
    the table), -1 where the window is not k linked runs or not in the sequence.

    Each window's key and link count from its own k runs: no run depends on the one before, so the loop
    over windows is vectorised (the usual k = 7 written out; a rolled key chains every run through a
    multiply)."""
    nw = nr - k + 1
    if k == 7 and A & (A - 1) == 0:
        # a power-of-two alphabet (two-shot: 4 codes): the key by shifts, read from the table with gathers (the
        # loop of 64-bit multiplies and a table read stayed scalar), then the link test (windows 0.46 -> 0.30 ms)
        s = 0
        while (1 << s) < A:
            s += 1
        if s == 2:
            # the two-shot alphabet: shifts by constants, which the compiler keeps in int32 lanes (shifts by a
            # variable amount it widened to int64: half the lanes)
            for j in range(nw):
                key = rc[j] | (rc[j + 1] << 2) | (rc[j + 2] << 4) | (rc[j + 3] << 6) | (rc[j + 4] << 8)
                keys[j] = key | (rc[j + 5] << 10) | (rc[j + 6] << 12)
        else:
            for j in range(nw):
                key = rc[j] | (rc[j + 1] << s) | (rc[j + 2] << 2 * s) | (rc[j + 3] << 3 * s) | (rc[j + 4] << 4 * s)
                keys[j] = key | (rc[j + 5] << 5 * s) | (rc[j + 6] << 6 * s)
        _gather(pos, table, keys, nw)
        for j in range(nw):
            # all six links (bools, and-ed: a sum of them in int64 took half the lanes)
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


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _increasing(x, n):
    """x[:n] made strictly increasing in place: a value not above the one before becomes that one + 1e-3.
    A vectorised test first: the values nearly always increase already, and the fix is sequential. (In place:
    a copy from an array to itself defeats the compiler's overlap check and runs scalar.)"""
    ok = True
    for r in range(1, n):
        ok &= x[r] > x[r - 1]
    if ok:
        return
    for r in range(1, n):
        x[r] = x[r - 1] + 1e-3 if x[r] <= x[r - 1] else x[r]


@njit(cache=True, nogil=True, inline="always")
def _window_label(c, t, period):
    """The label a confirmed window at position c gives its run t, -1 for no window (c < 0); int32 throughout
    (numba widens int32 arithmetic to int64, which would halve the vector)."""
    v = np.int32(c + t)
    v = np.int32(v - period) if v >= period else v
    return v if c >= 0 else np.int32(-1)


@njit(cache=True, nogil=True, inline="always")
def _merge_labels(a, b):
    """Two windows' int32 labels for one run: -1 none, -2 disagreeing (associative and commutative)."""
    return b if a == -1 else (a if (b == -1) | (b == a) else np.int32(-2))


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _confirmed_labels(nr, pos, lab, k, period, cw):
    """lab[i] = the label of run i from the confirmed windows over it (a window confirmed by an adjacent one
    that continues it), -1 where none, -2 where they disagree. cw: scratch for nr + k - 1 values.

    For the usual k = 7 in two branch-free vectorised passes (each window confirmed or not, then each run's
    label from its seven windows): the loop over windows below branches on every window and runs at a
    mispredicted branch per few runs. The same labels: continuing windows give their shared runs the same
    labels, so taking every confirmed window's labels changes nothing."""
    if k == 7 and nr >= 3:
        # cw[j + 6] = window j's position where it is confirmed, else -1 (and -1 before window 0); int32, so
        # the labels below are computed eight to a vector
        cw = cw.view(np.int32)
        none = np.int32(-1)
        for j in range(6):
            cw[j] = none
        per = np.int32(period)
        one = np.int32(1)
        for j in range(nr):
            # int32 throughout (numba widens int32 arithmetic to int64: half the lanes); positions are < period
            p = np.int32(pos[j])
            pp = np.int32(pos[j - 1]) if j > 0 else none
            pn = np.int32(pos[j + 1]) if j + 1 < nr else none
            after = _wrap(np.int32(pp + one), per)
            nxt = _wrap(np.int32(p + one), per)
            ok = ((pp >= 0) & (p == after)) | ((p >= 0) & (pn == nxt))
            cw[j + 6] = p if ok else none
        for i in range(nr):
            # window i - t gives run i the label p + t; the seven merged as a tree (the merge is associative)
            c0 = _window_label(cw[i + 6], 0, per)
            c1 = _window_label(cw[i + 5], 1, per)
            c2 = _window_label(cw[i + 4], 2, per)
            c3 = _window_label(cw[i + 3], 3, per)
            c4 = _window_label(cw[i + 2], 4, per)
            c5 = _window_label(cw[i + 1], 5, per)
            c6 = _window_label(cw[i], 6, per)
            lv = _merge_labels(
                _merge_labels(_merge_labels(c0, c1), _merge_labels(c2, c3)), _merge_labels(_merge_labels(c4, c5), c6)
            )
            lab[i] = lv
        return
    for i in range(nr):
        lab[i] = -1
    for j in range(nr):
        p = pos[j]
        if p < 0:
            continue
        # a window that continues the previous one confirms it too, and that one already gave runs
        # j..j+k-2 these same labels (or marked them -2): only the last run is new
        follows = j > 0 and pos[j - 1] >= 0 and p == _wrap(pos[j - 1] + 1, period)
        conf = follows or (j + 1 < nr and pos[j + 1] >= 0 and pos[j + 1] == _wrap(p + 1, period))
        if not conf:
            continue
        for t in range(k - 1 if follows else 0, k):
            i = j + t
            lv = _wrap(p + t, period)
            if lab[i] == -1:
                lab[i] = lv
            elif lab[i] != lv:
                lab[i] = -2


@njit(cache=True, nogil=True, inline="always")
def _column_at(q, line, lo_v, hi_v, use_range, lo, hi, y, xx):
    """The column of pixel xx = xa + q on its segment's line (line: float32 (column at xa, slope), interleaved),
    and whether it is kept: within the chain's column span [lo_v, hi_v] and, with use_range, the pixel's
    depth-range interval. float32 throughout: twice the lanes of float64, and the columns are stored as float32."""
    v = line[2 * q] + np.float32(q) * line[2 * q + 1]
    ok = (v >= lo_v) & (v <= hi_v)
    if use_range:
        ok &= (v >= lo[y, xx]) & (v <= hi[y, xx])
    return v, ok


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _segment_values(nx, nn, xa, nxp, first, seg_of, vals, out):
    """out[q] = vals[the segment of pixel xa + q] (q < nxp), the segments being those between the chain's nodes
    nx[:nn] (increasing): the one after the last interior node left of the pixel (the first segment extends
    left, the last right), i.e. the last interior node r whose first pixel right of it, s_r, is <= the pixel
    (s never decreases). first: scratch for nn values; seg_of (integer) scratch and out need room for nxp + 8."""
    short = True
    for r in range(1, nn - 1):
        first[r] = min(max(int(np.floor(nx[r])) + 1 - xa, 0), nxp)
    for r in range(1, nn - 2):
        short &= first[r + 1] - first[r] <= 8
    if short:
        # segments of at most 8 pixels (all but freak chains): each node writes its segment's value over the 8
        # pixels from its s_r, in order, so the next node overwrites the rest (a vector store per node; a segment
        # index per pixel cost a gather per pixel, and counting the nodes per pixel with a running sum a
        # dependent read-modify-write per node and per pixel)
        s1 = first[1] if nn > 2 else nxp
        v = vals[0]
        for q in range(s1):
            out[q] = v
        for r in range(1, nn - 1):
            _fill8(out, first[r], vals[r])
        if nn > 2:
            v = vals[nn - 2]
            for q in range(first[nn - 2] + 8, nxp):
                out[q] = v
        return
    for q in range(nxp + 1):
        seg_of[q] = 0
    for r in range(1, nn - 1):
        seg_of[first[r]] += 1
    seg = 0
    for q in range(nxp):
        seg += seg_of[q]
        seg_of[q] = seg
    _gather(out, vals, seg_of, nxp)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def _label_row(
    y,
    nr,
    rs,
    re,
    rc,
    link,
    edge,
    tl,
    pos,
    lab,
    nx,
    nv,
    table,
    A,
    k,
    period,
    sw,
    n_copies,
    proj_w,
    lo,
    hi,
    use_range,
    edges_mode,
    min_frac,
    smooth,
    work,
    marks,
    bounds,
    votes,
    out_col,
    out_chain,
    n_chains,
    span,
    tol,
    agree,
    disagree,
    npx,
):
    """Windows -> confirmed labels -> chains -> interpolated columns of row y. Returns n_chains.

    span[c] = (first, last) pixel chain c may write (when span has room for it: the fused path's vote counts
    walk these spans instead of whole rows). When npx has room for chain c, its pixels are counted into npx[c]
    and, against row y - 1 (labelled, not yet checked), its vertical votes within tol into agree[c] and
    disagree[c] as _row_votes would, while the columns are written (a pixel two chains share is counted for the
    later one, which writes it last).
    work (3, n) float64: row 0 the smoothed nodes; rows 1-2 the copy vote's range ends, then row 1 the segments'
    lines (float32 pairs) and row 2 the pixels' lines (see _segment_values). marks (3, n) int8 and bounds (2, n)
    int64: the chains' ends."""
    W = out_col.shape[1]
    cy = y % out_chain.shape[0]  # out_chain may hold the last rows only (a ring: see twoshot_rows)
    row_first = n_chains  # this row's first chain
    if nr < k:
        return n_chains
    sm = work[0]
    _window_positions(nr, rc, link, table, A, k, pos, tl)  # tl: free until the column write
    _confirmed_labels(nr, pos, lab, k, period, tl)
    # chains: maximal stretches of labelled runs, each linked to the next with the next label. Where each
    # starts and ends is marked in vectorised loops and the marks listed (a scan run by run branched on each)
    cont = marks[0]
    starts = marks[1]
    ends = marks[2]
    for i in range(nr):
        li = lab[i]
        nxt = lab[i + 1] if i + 1 < nr else -1
        cont[i] = link[i] & (li >= 0) & (nxt == _wrap(li + 1, period))
    for i in range(nr):
        labelled = lab[i] >= 0
        starts[i] = labelled & ((i == 0) or (cont[i - 1] == 0))
        ends[i] = labelled & (cont[i] == 0)
    n_found = _append_where(starts, nr, bounds[0])
    _append_where(ends, nr, bounds[1])
    for f in range(n_found):
        i0 = bounds[0, f]
        i1 = bounds[1, f]
        if i1 - i0 + 1 < k:
            continue
        base = lab[i0]
        # the nodes (stripe edges or centres) in plain vectorised loops; they must increase, and the rare chain
        # where they do not is made increasing by the sequential pass (a dependency from node to node)
        # (the chain's runs as views from i0: an index i0 + q of unknown sign gets numba's negative-index fix
        # per element, which made these loads gathers; the values are small multiples of 0.5, so the float sums
        # equal the integer products exactly)
        if edges_mode:
            nn = i1 - i0
            e_c = edge[i0:]
            v0 = (base + 1) * sw - 0.5
            for q in range(nn):
                nx[q] = e_c[q]
                nv[q] = v0 + q * sw
        else:
            nn = i1 - i0 + 1
            rs_c = rs[i0:]
            re_c = re[i0:]
            v0 = base * sw + 0.5 * (sw - 1)
            for q in range(nn):
                nx[q] = 0.5 * (rs_c[q] + re_c[q])
                nv[q] = v0 + q * sw
        if nn < 2:
            continue  # no segment to interpolate on (only with a window of k < 3 in the edges mode)
        _increasing(nx, nn)
        if smooth > 0 and nn > 2 * smooth:
            # noise in single edge positions averages out over a few neighbouring edges: replace each
            # node by a local straight-line fit x(v) over +-smooth nodes (surfaces are smooth within a chain)
            # The nodes' v are equally spaced (one stripe apart), so the fit is a fixed linear filter:
            # with window offsets q = 0..n-1 (n = 2 * smooth + 1) and the node at offset t, the fitted x
            # is sum_q x_q * (1 / n + (q - smooth) * (t - smooth) / S), S = sum_q (q - smooth)**2.
            nw = 2 * smooth + 1
            S = 0.0
            for q in range(nw):
                S += (q - smooth) * (q - smooth)
            inv_nw = 1.0 / nw
            # interior nodes: tc is 0, every weight is exactly 1 / n (the same sum, fewer operations); the
            # usual +-2 written out, so the loop over nodes has no inner loop and is vectorised. Read through
            # views from each offset: an index r - 2 of unknown sign gets numba's negative-index fix, which
            # made the five loads gathers and the store a scatter (a fifth of _label_row's time)
            if smooth == 2:
                x0 = nx[0:]
                x1 = nx[1:]
                x2 = nx[2:]
                x3 = nx[3:]
                x4 = nx[4:]
                s2 = sm[2:]
                for q in range(nn - 4):
                    acc = 0.0 + x0[q] * inv_nw + x1[q] * inv_nw + x2[q] * inv_nw
                    s2[q] = acc + x3[q] * inv_nw + x4[q] * inv_nw
            else:
                for r in range(smooth, nn - smooth):
                    acc = 0.0
                    for q in range(nw):
                        acc += nx[r - smooth + q] * inv_nw
                    sm[r] = acc
            # the end nodes fit the first or last window
            for e in range(2 * smooth):
                r = e if e < smooth else nn - 2 * smooth + e
                a0 = 0 if r < smooth else nn - nw
                tc = (r - a0 - smooth) / S
                xs = nx[a0:]
                acc = 0.0
                for q in range(nw):
                    acc += xs[q] * (1.0 / nw + (q - smooth) * tc)
                sm[r] = acc
            for r in range(nn):
                nx[r] = sm[r]
            _increasing(nx, nn)
        xa = rs[i0]  # the first and last whole pixel of the chain's end stripes
        xb = re[i1]
        if xa < 0:
            xa = 0
        if xb > W - 1:
            xb = W - 1
        if xb < xa:
            continue
        shift = 0.0
        if use_range:
            # each node (stripe edge or centre) votes for the copies that put its column inside the
            # depth-range interval of its pixel; the chain takes the clear winner, else no value
            copy_span = period * sw
            inv_span = 1.0 / copy_span  # a multiply, not a division (exact for the usual power-of-2 span)
            pw = proj_w - 0.5
            # node r votes for copies q >= q0 (the first whose column reaches lo) while v + q span <= hi: the
            # pixels' range ends gathered first, then each copy's count as a vectorised sum over the nodes
            # (a per-node loop over copies with table reads stayed scalar)
            xr = pos  # free once the labels are confirmed
            for r in range(nn):
                xr[r] = min(max(int(nx[r] + 0.5), 0), W - 1)
            glo = work[1]
            ghi = work[2]
            _gather(glo, lo[y], xr, nn)
            _gather(ghi, hi[y], xr, nn)
            q0 = xr
            for r in range(nn):
                v = nv[r]
                hv = ghi[r]
                ghi[r] = pw if hv > pw else hv
                # clamped in float: int() of NaN or of values past int64 is undefined (x86 gives INT64_MIN)
                qf = np.ceil((glo[r] - v) * inv_span)
                q0[r] = int(min(qf, n_copies)) if qf > 0.0 else 0
            if n_copies <= 4:
                # the usual few copies counted in one pass over the nodes (a pass per copy repeats the loop's
                # set-up and scalar tail per copy, for ~85 nodes)
                c0 = 0
                c1 = 0
                c2 = 0
                c3 = 0
                for r in range(nn):
                    v = nv[r]
                    hv = ghi[r]
                    qr = q0[r]
                    c0 += (qr <= 0) & (v <= hv)
                    c1 += (qr <= 1) & (v + copy_span <= hv)
                    c2 += (qr <= 2) & (v + 2 * copy_span <= hv)
                    c3 += (qr <= 3) & (v + 3 * copy_span <= hv)
                votes[0] = c0
                if n_copies > 1:
                    votes[1] = c1
                if n_copies > 2:
                    votes[2] = c2
                if n_copies > 3:
                    votes[3] = c3
            else:
                for q in range(n_copies):
                    cnt = 0
                    offset = q * copy_span
                    for r in range(nn):
                        cnt += (q >= q0[r]) & (nv[r] + offset <= ghi[r])
                    votes[q] = cnt
            best_q = -1
            best_n = 0
            second_n = 0
            for q in range(n_copies):
                cnt = votes[q]
                if cnt > best_n:
                    second_n = best_n
                    best_n = cnt
                    best_q = q
                elif cnt > second_n:
                    second_n = cnt
            if best_q < 0 or best_n < min_frac * nn or second_n > 0.5 * best_n:
                continue
            shift = best_q * copy_span
        # pixels of the end stripes lie within one stripe of the outer edges; beyond is a guess
        lo_v = nv[0] - END_EXT * sw if edges_mode else nv[0] - 0.5 * sw
        hi_v = nv[nn - 1] + END_EXT * sw if edges_mode else nv[nn - 1] + 0.5 * sw
        # each segment's line once per chain, as a float32 pair in one int64: its column at the chain's first pixel
        # xa, with the copy's shift, and its slope (no division per pixel). Every pixel then gets its segment's
        # pair (see _segment_values), so the loop that interpolates reads a plain row and is vectorised
        nxp = xb - xa + 1
        lines = work[1].view(np.float32)
        for r in range(nn - 1):
            slope = (nv[r + 1] - nv[r]) / (nx[r + 1] - nx[r])
            lines[2 * r] = np.float32(nv[r] + shift + (xa - nx[r]) * slope)
            lines[2 * r + 1] = np.float32(slope)
        line = work[2].view(np.float32)
        # (tl is free once the windows are looked up, pos after the copy vote)
        _segment_values(nx, nn, xa, nxp, pos, tl, work[1].view(np.int64), work[2].view(np.int64))
        lo_v = np.float32(lo_v + shift)
        hi_v = np.float32(hi_v + shift)
        if n_chains < npx.shape[0]:
            # the row above is read at y - 1 >= 0 and its votes masked at y = 0 (one loop, vectorised)
            up = max(y - 1, 0)
            cu = up % out_chain.shape[0]
            above = y > 0
            tol32 = np.float32(tol)
            # the zero-crossing runs of neighbouring stripes share a pixel when the crossing falls exactly on
            # it, so the row's previous chain may own this chain's first pixel: if this chain takes it, that
            # pixel's count and vote move here (as counting the finished row would have it)
            shared = -1
            shared_col = np.float32(0.0)
            if n_chains > row_first and n_chains - 1 < span.shape[0]:
                pe = span[n_chains - 1, 1]
                if pe >= xa and out_chain[cy, pe] == n_chains - 1:
                    shared = pe
                    shared_col = out_col[y, pe]
            n = 0
            ag = 0
            dg = 0
            for q in range(nxp):
                xx = xa + q
                v32, ok = _column_at(q, line, lo_v, hi_v, use_range, lo, hi, y, xx)
                if ok:
                    out_col[y, xx] = v32
                    out_chain[cy, xx] = n_chains
                n += ok
                pair = ok & above & (out_chain[cu, xx] >= 0)
                close = abs(out_col[up, xx] - v32) <= tol32
                ag += pair & close
                dg += pair & (not close)
            npx[n_chains] = n
            agree[n_chains] = ag
            disagree[n_chains] = dg
            if shared >= 0 and out_chain[cy, shared] == n_chains:
                npx[n_chains - 1] -= 1
                if above and out_chain[cu, shared] >= 0:
                    if abs(out_col[up, shared] - shared_col) <= tol32:
                        agree[n_chains - 1] -= 1
                    else:
                        disagree[n_chains - 1] -= 1
        else:
            for q in range(nxp):
                xx = xa + q
                v, ok = _column_at(q, line, lo_v, hi_v, use_range, lo, hi, y, xx)
                if ok:
                    out_col[y, xx] = v
                    out_chain[cy, xx] = n_chains
        if n_chains < span.shape[0]:
            span[n_chains, 0] = xa
            span[n_chains, 1] = xb
        n_chains += 1
    return n_chains


@njit(cache=True, nogil=True, error_model="numpy")
def label_rows(
    code,
    feat,
    wts,
    link_ok,
    table,
    k,
    period,
    sw,
    n_copies,
    proj_w,
    gap_max,
    lo,
    hi,
    use_range,
    edges_mode,
    min_frac,
    events,
    noise,
    smooth,
    out_col,
    out_chain,
):
    """Rows -> sub-pixel projector columns (NaN = none). Returns the number of chains.

    Stripes come from pixel runs of equal code (events=False) or, for two-shot, from the zero
    crossings of each channel (events=True). lo/hi: per pixel, the projector columns the depth
    range allows (use_range); the copy of a periodic sequence is chosen per chain as the one whose
    columns fall inside that interval for at least min_frac of its pixels, with no other copy
    close: else no value.
    """
    H, W = code.shape
    m = feat.shape[2]
    A = link_ok.shape[0]
    n = (m + 1) * (2 * W + 8)
    rs, re, rc, link, edge, left, right, tl, pos, lab, nx, nv, sm, marks, bounds, votes = _row_scratch(n, W, n_copies)
    ex = np.empty((m, n), np.float64)
    es = np.empty((m, n), np.int64)
    et = np.empty((m, n), np.int64)
    cnt = np.zeros(m, np.int64)
    ps = np.zeros((2, m), np.int64)
    no_span = np.empty((0, 2), np.int32)
    no_count = np.empty(0, np.int32)
    n_chains = 0
    trans = _transitions(wts, link_ok, n)
    for y in range(H):
        if events:
            nr = _event_runs(feat[y].T, noise[y].T, gap_max, ex, es, et, cnt, ps, rs, re, rc, link, edge, left, right)
        else:
            nr = _pixel_runs(code[y], feat[y].T, wts, trans, gap_max, rs, re, rc, link, edge)
        n_chains = _label_row(
            y,
            nr,
            rs,
            re,
            rc,
            link,
            edge,
            tl,
            pos,
            lab,
            nx,
            nv,
            table,
            A,
            k,
            period,
            sw,
            n_copies,
            proj_w,
            lo,
            hi,
            use_range,
            edges_mode,
            min_frac,
            smooth,
            sm,
            marks,
            bounds,
            votes,
            out_col,
            out_chain,
            n_chains,
            no_span,
            0.0,
            no_count,
            no_count,
            no_count,
        )
    return n_chains


@njit(cache=True, nogil=True, inline="always")
def _unconfirmed(agree, disagree, npx, min_support):
    """The vertical check's verdict on a chain: no more agreeing than disagreeing vertical neighbours, or
    fewer than min_support agreeing ones per pixel."""
    return disagree >= agree or agree < min_support * npx


@njit(cache=True, nogil=True, error_model="numpy")
def vertical_check(out_col, out_chain, n_chains, tol, min_support):
    """Keep a chain only where the rows above and below confirm it.

    Every labelled neighbour (y +- 1, same x) within tol projector px agrees, any other disagrees.
    A chain survives if it has more agreements than disagreements and at least min_support
    agreements per pixel: a two-shot window sequence is any walk of one-bit changes, so a chain
    made of noise (shadow, black surface) matches the sequence by chance far too easily, but it
    never lines up with the rows next to it.
    """
    H, W = out_col.shape
    nc = max(n_chains, 1)
    agree = np.zeros(nc, np.int32)
    disagree = np.zeros(nc, np.int32)
    npx = np.zeros(nc, np.int32)
    for y in range(H):
        for x in range(W):
            c = out_chain[y, x]
            if c < 0:
                continue
            npx[c] += 1
            v = out_col[y, x]
            for dy in (-1, 1):
                yy = y + dy
                if yy < 0 or yy >= H:
                    continue
                if out_chain[yy, x] < 0:
                    continue
                if abs(out_col[yy, x] - v) <= tol:
                    agree[c] += 1
                else:
                    disagree[c] += 1
    drop = np.zeros(nc, np.bool_)
    dropped = 0
    for c in range(n_chains):
        if _unconfirmed(agree[c], disagree[c], npx[c], min_support):
            drop[c] = True
            dropped += 1
    if dropped:
        for y in range(H):
            for x in range(W):
                c = out_chain[y, x]
                if c >= 0 and drop[c]:
                    out_col[y, x] = np.nan
                    out_chain[y, x] = -1
    return dropped


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def _classify_row(f1, f2, y, lin, dlin, pk, unmix, t_abs, t_rel, t_rel_edge, block, bmax, tmp, want_thr, code, ahead):
    """twoshot_classify for row y of the frames: codes into code (W,), the unmixed differences into
    tmp[0:m] and, with want_thr, the zero-crossing sign thresholds into tmp[m:2m] (tmp is (2m + 2, W); the
    last two rows are scratch). ahead: the rows to prefetch meanwhile (see _differences).

    Same arithmetic in three simple loops: differences and noise floors into the contiguous rows of
    tmp, block maxima, then thresholds. Coefficients live in locals and each loop writes one kind of
    array: the output buffers are float32 like the tables, so the compiler must assume they alias and
    reloads whatever lives in an array after every store; interleaved (x, channel) stores also kept
    the threshold loop from being vectorised. Written out for the usual two pattern channels; bmax is
    (4, nb + 2) here (block maxima, then thresholds). Any other channel count takes _classify_row_any.
    """
    if unmix.shape[0] != 2:
        _classify_row_any(f1, f2, y, lin, dlin, unmix, t_abs, t_rel, t_rel_edge, block, bmax, tmp, code)
        return
    W = code.shape[0]
    nb = (W + block - 1) // block
    if bmax.shape[0] < 4 or bmax.shape[1] < nb + 2:
        raise ValueError("_classify_row: bmax needs (4, nb + 2) for two channels")
    ta = t_abs * np.float32(0.5)
    fv0 = tmp[0]
    fv1 = tmp[1]
    nz0 = tmp[2]
    nz1 = tmp[3]
    _differences(f1, f2, y, lin, dlin, pk, unmix, ta, tmp, ahead)
    # block maxima of |d| at bmax[c, 1 + b], with zero guards at both ends
    bm0 = bmax[0]
    bm1 = bmax[1]
    bm0[0] = 0.0
    bm1[0] = 0.0
    bm0[nb + 1] = 0.0
    bm1[nb + 1] = 0.0
    # whole blocks of the usual 8 pixels written out (a loop of unknown length per block costs a vector
    # loop's set-up and its scalar tail every 8 pixels); the rest, and other block sizes, in the loop
    nb8 = W // 8 if block == 8 else 0
    z = np.float32(0.0)
    for b in range(nb8):
        x0 = b * 8
        # each leaf pair starts from 0 like the loop below, so a NaN is skipped there too (max(a, b) keeps a
        # unless b > a: a NaN first operand would win)
        m0 = max(
            max(max(max(z, abs(fv0[x0])), abs(fv0[x0 + 1])), max(max(z, abs(fv0[x0 + 2])), abs(fv0[x0 + 3]))),
            max(max(max(z, abs(fv0[x0 + 4])), abs(fv0[x0 + 5])), max(max(z, abs(fv0[x0 + 6])), abs(fv0[x0 + 7]))),
        )
        m1 = max(
            max(max(max(z, abs(fv1[x0])), abs(fv1[x0 + 1])), max(max(z, abs(fv1[x0 + 2])), abs(fv1[x0 + 3]))),
            max(max(max(z, abs(fv1[x0 + 4])), abs(fv1[x0 + 5])), max(max(z, abs(fv1[x0 + 6])), abs(fv1[x0 + 7]))),
        )
        bm0[b + 1] = m0
        bm1[b + 1] = m1
    for b in range(nb8, nb):
        x0 = b * block
        x1 = min(W, x0 + block)
        m0 = np.float32(0.0)
        m1 = np.float32(0.0)
        for x in range(x0, x1):
            m0 = max(m0, abs(fv0[x]))
            m1 = max(m1, abs(fv1[x]))
        bm0[b + 1] = m0
        bm1[b + 1] = m1
    # the local amplitude, max |d| over a block and its two neighbours, times t_rel: spread over the block's
    # pixels first, so the per-pixel loop below reads plain rows and is vectorised (a block index per pixel
    # kept it scalar, at five times the time)
    q0 = tmp[4]
    q1 = tmp[5]
    # each block's threshold in a vectorised loop (into bmax's rows 2-3), then whole pairs of 8-pixel blocks
    # spread with one 16-lane store each (a scalar loop over blocks with a vector store per block was ~5 % of the
    # decoder at 640 x 480), the rest in the loop
    tb0 = bmax[2]
    tb1 = bmax[3]
    for b in range(nb):
        tb0[b] = t_rel * max(bm0[b + 1], max(bm0[b], bm0[b + 2]))
        tb1[b] = t_rel * max(bm1[b + 1], max(bm1[b], bm1[b + 2]))
    n16 = W // 16 if block == 8 else 0
    for i in range(n16):
        spread8x2(tb0, 2 * i, q0, 16 * i)
        spread8x2(tb1, 2 * i, q1, 16 * i)
    for b in range(2 * n16, nb):
        for x in range(b * block, min(W, (b + 1) * block)):
            q0[x] = tb0[b]
            q1[x] = tb1[b]
    for x in range(W):
        d0 = fv0[x]
        d1 = fv1[x]
        t0 = q0[x]
        t1 = q1[x]
        n0 = nz0[x]
        n1 = nz1[x]
        t0 = t0 if t0 >= n0 else n0
        t1 = t1 if t1 >= n1 else n1
        # bitwise & and a select, not `and`/`if`: no branch per pixel (signs flip every few pixels)
        ok = (abs(d0) >= t0) & (abs(d1) >= t1)
        bits = np.int32(d0 < 0) + 2 * np.int32(d1 < 0)
        code[x] = np.int8(bits if ok else -1)
    if want_thr:
        for b in range(nb):
            a0 = max(bm0[b + 1], max(bm0[b], bm0[b + 2]))
            a1 = max(bm1[b + 1], max(bm1[b], bm1[b + 2]))
            te0 = t_rel_edge * a0
            te1 = t_rel_edge * a1
            for x in range(b * block, min(W, (b + 1) * block)):
                nz0[x] = max(te0, nz0[x])  # the zero-crossing segmentation's sign thresholds
                nz1[x] = max(te1, nz1[x])


def _differences(f1, f2, y, lin, dlin, pk, unmix, ta, tmp, ahead):
    """Row y's unmixed differences and noise floors of the two pattern channels into tmp[0:4] (compiled only:
    the overload below picks the gathers of simd.differences16 for C-contiguous frames and tables, else the loop).
    ahead: (2-D float32 C array, row) pairs whose rows the pair tables' loop asks the caches for, a line per 16
    pixels (simd.prefetch_at: a hint, no effect on values)."""
    raise NotImplementedError("numba only")


@overload(_differences, jit_options={"nogil": True, "error_model": "numpy", "_nrt": False})
def _differences_impl(f1, f2, y, lin, dlin, pk, unmix, ta, tmp, ahead):
    if f1 == f2 and differences16_takes(f1, lin, dlin, unmix, ta, tmp) and _c_array(pk) and pk.dtype == types.int64:

        def vector(f1, f2, y, lin, dlin, pk, unmix, ta, tmp, ahead):
            if f1.shape[2] != 3 or lin.shape[0] != 3 or dlin.shape[0] != 3:
                _differences_loop(f1, f2, y, lin, dlin, unmix, ta, tmp)
                return
            W = f1.shape[1]
            a = f1[y]
            b = f2[y]
            u00, u01, u02 = unmix[0, 0], unmix[0, 1], unmix[0, 2]
            u10, u11, u12 = unmix[1, 0], unmix[1, 1], unmix[1, 2]
            x = 0
            if pk.shape[0] == lin.size:  # the tables packed in pairs (pack_tables): half the gathered elements
                while x + LANES <= W:
                    differences16(a, b, pk, pk, u00, u01, u02, u10, u11, u12, ta, tmp, x)
                    x += LANES
            elif lin.shape[1] == 256 and (pk.shape[0] == PAIR_ENTRIES or pk.shape[0] == 3 * PAIR_ENTRIES):
                # a table over 8-bit value pairs (pair_tables): one gather per channel for both frames
                x = _pair_differences(a, b, pk, u00, u01, u02, u10, u11, u12, ta, tmp, ahead)
            if x + LANES <= W:  # (a reshape is a runtime call: only where the flat tables are read)
                lf = lin.reshape(lin.size)
                df = dlin.reshape(dlin.size)
                while x + LANES <= W:
                    differences16(a, b, lf, df, u00, u01, u02, u10, u11, u12, ta, tmp, x)
                    x += LANES
            _row_differences(
                a[x:], b[x:], lin[0], lin[1], lin[2], dlin[0], dlin[1], dlin[2], u00, u01, u02, u10, u11, u12, ta,
                tmp[0, x:], tmp[1, x:], tmp[2, x:], tmp[3, x:],
            )  # fmt: skip

        return vector

    def scalar(f1, f2, y, lin, dlin, pk, unmix, ta, tmp, ahead):
        _differences_loop(f1, f2, y, lin, dlin, unmix, ta, tmp)

    return scalar


def _pair_differences(a, b, pairs, u00, u01, u02, u10, u11, u12, ta, tmp, ahead):
    """_differences of the row's whole groups of 16 pixels from a pair table (differences16_pairs) for 8-bit
    frames, with ahead's prefetches; returns the pixels done (0 for other frames: the caller goes on with the
    other tables)."""
    raise NotImplementedError("numba only")


@overload(_pair_differences, jit_options={"nogil": True, "error_model": "numpy", "_nrt": False})
def _pair_differences_impl(a, b, pairs, u00, u01, u02, u10, u11, u12, ta, tmp, ahead):
    if a.dtype == types.uint8:

        def eight_bit(a, b, pairs, u00, u01, u02, u10, u11, u12, ta, tmp, ahead):
            x = 0
            while x + LANES <= a.shape[0]:
                # the lines of the rows read later at these pixels, asked for among the gathers (which leave the
                # memory system idle; a burst of prefetches per row stalled on the line fill buffers instead)
                for arr, row in ahead:
                    prefetch_at(arr, row, min(x, arr.shape[1] - 1))
                differences16_pairs(a, b, pairs, u00, u01, u02, u10, u11, u12, ta, tmp, x)
                x += LANES
            return x

        return eight_bit

    def other(a, b, pairs, u00, u01, u02, u10, u11, u12, ta, tmp, ahead):
        return 0

    return other


@njit(nogil=True, error_model="numpy", _nrt=False)
def _differences_loop(f1, f2, y, lin, dlin, unmix, ta, tmp):
    _row_differences(
        f1[y], f2[y], lin[0], lin[1], lin[2], dlin[0], dlin[1], dlin[2], unmix[0, 0], unmix[0, 1], unmix[0, 2],
        unmix[1, 0], unmix[1, 1], unmix[1, 2], ta, tmp[0], tmp[1], tmp[2], tmp[3],
    )  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _row_differences(a, b, l0, l1, l2, dl0, dl1, dl2, u00, u01, u02, u10, u11, u12, ta, fv0, fv1, nz0, nz1):
    """Unmixed linear frame2 - frame1 of the two pattern channels, and their noise floors, for one row."""
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


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _classify_row_any(f1, f2, y, lin, dlin, unmix, t_abs, t_rel, t_rel_edge, block, bmax, tmp, code):
    """_classify_row for any number of pattern channels (its thresholds are always written)."""
    W = code.shape[0]
    m = unmix.shape[0]
    nb = (W + block - 1) // block
    ta = t_abs * 0.5
    for c in range(m):
        u0 = unmix[c, 0]
        u1 = unmix[c, 1]
        u2 = unmix[c, 2]
        w0 = abs(u0)
        w1 = abs(u1)
        w2 = abs(u2)
        for b in range(nb):
            x0 = b * block
            x1 = min(W, x0 + block)
            mx = np.float32(-np.inf)
            for x in range(x0, x1):
                a0 = f1[y, x, 0]
                a1 = f1[y, x, 1]
                a2 = f1[y, x, 2]
                b0 = f2[y, x, 0]
                b1 = f2[y, x, 1]
                b2 = f2[y, x, 2]
                d0 = lin[0, b0] - lin[0, a0]
                d1 = lin[1, b1] - lin[1, a1]
                d2 = lin[2, b2] - lin[2, a2]
                n0 = dlin[0, b0] + dlin[0, a0]
                n1 = dlin[1, b1] + dlin[1, a1]
                n2 = dlin[2, b2] + dlin[2, a2]
                fv = u0 * d0 + u1 * d1 + u2 * d2
                tmp[c, x] = fv
                tmp[m + c, x] = ta * (w0 * n0 + w1 * n1 + w2 * n2)
                av = abs(fv)
                if av > mx:
                    mx = av
            bmax[c, b] = mx
    for x in range(W):
        code[x] = 0
    for c in range(m):
        bit = 1 << c
        prev = np.float32(0.0)
        cur = bmax[c, 0]
        for b in range(nb):
            nxt = bmax[c, b + 1] if b + 1 < nb else np.float32(0.0)
            a = cur
            if b > 0 and prev > a:
                a = prev
            if nxt > a:
                a = nxt
            tr = t_rel * a
            te = t_rel_edge * a
            x0 = b * block
            x1 = min(W, x0 + block)
            for x in range(x0, x1):
                nz = tmp[m + c, x]
                d = tmp[c, x]
                thr = tr if tr >= nz else nz
                cd = code[x]
                if not abs(d) >= thr:  # (NaN: no sign, as in _classify_row and the numpy reference)
                    cd = -1
                elif d < 0 and cd >= 0:
                    cd |= bit
                code[x] = cd
                tmp[m + c, x] = te if te > nz else nz  # the zero-crossing segmentation's threshold
            prev = cur
            cur = nxt


@njit(cache=True, nogil=True, error_model="numpy")
def pack_tables(lin, dlin):
    """The linearisation and noise-slope tables (3, levels) float32 as one int64 table whose entry i holds the
    float32 pair (lin, dlin) of flat entry i (the gathered differences read both with one 8-byte gather; an
    empty table for tables of different shapes). Built once per decoder (TwoShotDecoder.tables): for 16-bit
    frames 3 x 65536 entries, 1.5 MB, ~10 % less decode time than two 4-byte gathers (when it ran per frame
    it cost more than it saved); 8-bit frames read pair_tables instead."""
    if lin.shape != dlin.shape:
        return np.empty(0, np.int64)
    C, levels = lin.shape
    pk = np.empty(C * levels, np.int64)
    pairs = pk.view(np.float32)
    for c in range(C):
        for v in range(levels):
            pairs[2 * (c * levels + v)] = lin[c, v]
            pairs[2 * (c * levels + v) + 1] = dlin[c, v]
    return pk


PAIR_ENTRIES = 256 * 256  # a pair table's entries per channel (8-bit frames)


@njit(cache=True, nogil=True, error_model="numpy")
def pair_tables(lin, dlin):
    """For 8-bit frames (tables (3, 256) float32), the int64 table over value pairs that differences16_pairs
    reads: entry c * PAIR_ENTRIES + 256 a + b holds the float32 pair (lin[c, b] - lin[c, a], dlin[c, b] +
    dlin[c, a]), one table of PAIR_ENTRIES for all three channels when their tables are equal (512 KB), else
    three; an empty table for other tables. Built once per decoder (TwoShotDecoder.tables)."""
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
    pairs = pk.view(np.float32)
    for c in range(C):
        for a in range(256):
            for b in range(256):
                i = c * PAIR_ENTRIES + 256 * a + b
                pairs[2 * i] = lin[c, b] - lin[c, a]
                pairs[2 * i + 1] = dlin[c, b] + dlin[c, a]
    return pk


@njit(cache=True, nogil=True, error_model="numpy")
def twoshot_rows(
    f1,
    f2,
    lin,
    dlin,
    pk,
    unmix,
    t_abs,
    t_rel,
    t_rel_edge,
    block,
    wts,
    link_ok,
    table,
    k,
    period,
    sw,
    n_copies,
    proj_w,
    gap_max,
    lo,
    hi,
    use_range,
    edges_mode,
    min_frac,
    smooth,
    tol,
    min_support,
    mode,
    col_e,
    chain_e,
    col_r,
    chain_r,
    moebius,
    w0,
    w_span,
    depth,
):
    """The two-shot decoder's "both" segmentation fused row by row: classify a row into one-row buffers,
    label it from its zero crossings (col_e/chain_e) and from its pixel runs (col_r/chain_r), count the
    vertical agreement with the row above, and finish the row above (vertical check + merge).

    Same result as twoshot_classify, label_rows twice, vertical_check on both and merge_maps, without
    full-image intermediates or extra passes: chains are row segments, so a chain of row y - 1 has all
    its vertical votes once row y is labelled. The merged map is written into col_e/chain_e; the chain maps may
    hold the last R >= 2 rows only (row y at y % R: the rows the vertical check compares), the column maps all;
    a value filled from the runs map gets chain id (runs chain + cap). tol <= 0 skips the vertical check.
    mode: 0 = the zero-crossing stripes alone ("events"), 1 = the pixel runs alone ("runs", into col_e/chain_e),
    2 = both merged ("both"); col_r/chain_r are only used by mode 2. The maps need no initialisation (a confidence
    map is not written: it would be 1 where a value, else 0; StripeMap makes it if read). pk: the tables read
    together, built once per decoder (TwoShotDecoder.tables: pair_tables for 8-bit frames, else pack_tables).
    moebius (3, H, W), w0, w_span and depth (H, W): with a depth map of the frames' size, each row is triangulated
    as soon as its columns are final (app.triangulate.moebius_depth_row, while the row is in cache: a pass over
    the finished column map reads it back from memory); pass a (0, 0) depth map for none.
    Returns (events chains, runs chains, events dropped, runs dropped, filled, clashes).
    """
    H, W = col_e.shape
    if chain_e.shape[0] < 2 or chain_e.shape[1] != W or (mode == 2 and (chain_r.shape[0] < 2 or chain_r.shape[1] != W)):
        raise ValueError("twoshot_rows: a chain map needs the frames' width and at least two rows")
    want_depth = depth.shape == col_e.shape
    if want_depth and (moebius.shape[1] != H or moebius.shape[2] != W):
        raise ValueError("twoshot_rows: the Moebius planes differ in size from the frames")
    m = unmix.shape[0]
    A = link_ok.shape[0]
    nb = (W + block - 1) // block
    bmax = np.empty((max(m, 2) * 2, nb + 2), np.float32)  # block maxima, then (two channels) block thresholds
    # the row's differences (0..m-1), sign thresholds (m..2m-1) and _classify_row's scratch
    tmp = np.empty((2 * m + 2, W), np.float32)
    code = np.empty(W, np.int8)
    n = (m + 1) * (2 * W + 8)
    rs, re, rc, link, edge, left, right, tl, pos, lab, nx, nv, sm, marks, bounds, votes = _row_scratch(n, W, n_copies)
    ex = np.empty((m, n), np.float64)
    es = np.empty((m, n), np.int64)
    et = np.empty((m, n), np.int64)
    cnt = np.zeros(m, np.int64)
    ps = np.zeros((2, m), np.int64)
    cap = H * (n // k + 2)  # at most this many chains: each holds k runs of a row
    # per-chain counts and spans, each written before it is read (_label_row, _row_votes): no zeroing
    agree_e = np.empty(cap, np.int32)
    dis_e = np.empty(cap, np.int32)
    npx_e = np.empty(cap, np.int32)
    cap_r = cap if mode == 2 else 1  # the runs map of "both" only
    agree_r = np.empty(cap_r, np.int32)
    dis_r = np.empty(cap_r, np.int32)
    npx_r = np.empty(cap_r, np.int32)
    span_e = np.empty((cap, 2), np.int32)
    span_r = np.empty((cap_r, 2), np.int32)
    first_e = np.zeros(H + 1, np.int64)  # chains of row y are first_e[y] .. first_e[y + 1] - 1
    first_r = np.zeros(H + 1, np.int64)
    check = tol > 0
    trans = _transitions(wts, link_ok, n)
    stats = np.zeros(4, np.int64)  # dropped events, dropped runs, filled, clashes
    n_e, n_r = _rows(
        f1, f2, lin, dlin, pk, unmix, t_abs, t_rel, t_rel_edge, block, bmax, tmp, code, mode, wts, trans, gap_max,
        (rs, re, rc, link, edge, left, right, tl, pos, lab, nx, nv, sm, marks, bounds, votes), (ex, es, et, cnt, ps),
        table, A, k, period, sw, n_copies, proj_w, lo, hi, use_range, edges_mode, min_frac, smooth,
        (col_e, chain_e, col_r, chain_r), (agree_e, dis_e, npx_e, span_e, first_e),
        (agree_r, dis_r, npx_r, span_r, first_r), tol, check, min_support, cap, stats,
        (moebius[0], moebius[1], moebius[2], np.float32(w0), np.float32(w_span), depth, want_depth),
    )  # fmt: skip
    return n_e, n_r, stats[0], stats[1], stats[2], stats[3]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _rows(
    f1, f2, lin, dlin, pk, unmix, t_abs, t_rel, t_rel_edge, block, bmax, tmp, code, mode, wts, trans, gap_max,
    scratch, events, table, A, k, period, sw, n_copies, proj_w, lo, hi, use_range, edges_mode, min_frac, smooth,
    maps, counts_e, counts_r, tol, check, min_support, cap, stats, geometry,
):  # fmt: skip
    """twoshot_rows' loop over the rows, in a kernel of its own without reference counting (the row views and
    calls of a reference-counted loop cost ~3 % of the decoder in atomic runtime calls). Returns (n_e, n_r).

    The per-row kernels (_classify_row, _pixel_runs, _label_row, _row_votes) are compiled with forceinline, which
    the kernels compiled for them inherit: LLVM inlines them all into this loop. Each call had passed its arrays
    as numba's 7-9-word structs (~250 words a row for _label_row) and reloaded their fields; inlined, ~4-6 % less
    time at 640 x 480 and ~3.5 % at 1280 x 1024, for ~7 s more on the first (uncached) compile."""
    rs, re, rc, link, edge, left, right, tl, pos, lab, nx, nv, sm, marks, bounds, votes = scratch
    ex, es, et, cnt, ps = events
    col_e, chain_e, col_r, chain_r = maps
    agree_e, dis_e, npx_e, span_e, first_e = counts_e
    agree_r, dis_r, npx_r, span_r, first_r = counts_r
    ca, cb, cc, w0f, wsf, depth, want_depth = geometry
    H = col_e.shape[0]
    m = unmix.shape[0]
    fr = tmp[:m]
    tr = tmp[m:]
    n_e = 0
    n_r = 0
    for y in range(H):
        # the maps come uninitialised: each row is cleared just before it is labelled (while it is in cache)
        col_e[y] = np.nan
        chain_e[y % chain_e.shape[0]] = -1
        if mode == 2:
            col_r[y] = np.nan
            chain_r[y % chain_r.shape[0]] = -1
        # rows to fetch while row y's differences are gathered: the geometry of row y, triangulated next time
        # round, the column range of row y + 1, read at its stripes' nodes (at addresses no hardware
        # prefetcher guesses), and the column map's row y + 1, cleared next time round (its store waited on the
        # lines: ~2 % at 1280 x 1024); when there is no depth map or range, their (1, 1) stand-ins
        ahead = (
            (ca, min(y, ca.shape[0] - 1)),
            (cb, min(y, cb.shape[0] - 1)),
            (cc, min(y, cc.shape[0] - 1)),
            (lo, min(y + 1, lo.shape[0] - 1)),
            (hi, min(y + 1, hi.shape[0] - 1)),
            (col_e, min(y + 1, H - 1)),
        )
        _classify_row(
            f1, f2, y, lin, dlin, pk, unmix, t_abs, t_rel, t_rel_edge, block, bmax, tmp, mode != 1, code, ahead
        )
        if mode == 1:
            nr = _pixel_runs(code, fr, wts, trans, gap_max, rs, re, rc, link, edge)
        else:
            nr = _event_runs(fr, tr, gap_max, ex, es, et, cnt, ps, rs, re, rc, link, edge, left, right)
        n_e = _label_row(
            y, nr, rs, re, rc, link, edge, tl, pos, lab, nx, nv, table, A, k, period, sw, n_copies, proj_w,
            lo, hi, use_range, edges_mode, min_frac, smooth, sm, marks, bounds, votes, col_e, chain_e, n_e, span_e,
            tol, agree_e, dis_e, npx_e,
        )  # fmt: skip
        if mode == 2:
            nr = _pixel_runs(code, fr, wts, trans, gap_max, rs, re, rc, link, edge)
            n_r = _label_row(
                y, nr, rs, re, rc, link, edge, tl, pos, lab, nx, nv, table, A, k, period, sw, n_copies, proj_w,
                lo, hi, use_range, edges_mode, min_frac, smooth, sm, marks, bounds, votes, col_r, chain_r, n_r,
                span_r, tol, agree_r, dis_r, npx_r,
            )  # fmt: skip
        first_e[y + 1] = n_e
        first_r[y + 1] = n_r
        if check:  # (the pixel counts _finish_row reads come from _label_row)
            _row_votes(col_e, chain_e, y, tol, agree_e, dis_e, npx_e, first_e, span_e)
            if mode == 2:
                _row_votes(col_r, chain_r, y, tol, agree_r, dis_r, npx_r, first_r, span_r)
        for yy in range(y - 1, y + 1 if y == H - 1 else y):
            if yy < 0:
                continue
            if mode == 2:
                _finish_row(yy, col_e, chain_e, col_r, chain_r, first_e, first_r, agree_e, dis_e, npx_e,
                            agree_r, dis_r, npx_r, check, min_support, cap, stats)  # fmt: skip
            elif check:  # one map: only the dropped chains' pixels change
                stats[0] += _drop_chains(yy, col_e, chain_e, first_e, agree_e, dis_e, npx_e, span_e, min_support)
            if want_depth:
                moebius_depth_row(col_e, ca, cb, cc, yy, w0f, wsf, depth)
    return n_e, n_r


@njit(cache=True, nogil=True, error_model="numpy")
def _row_scratch(n, W, n_copies):
    """The per-row buffers of the run segmentation and _label_row, for at most n runs in a row of W pixels."""
    # the runs' bounds, codes, window positions and chain ends in int32: run_bounds16 and append_where16 compress
    # sixteen to a register (int64: two halves of eight), and the loops over runs load half the bytes (decode +
    # triangulate 0.97x at 640x480 and 1280x1024 for the runs, 0.97-0.99x and 0.96-0.98x more for the rest)
    rs = np.empty(n, np.int32)
    re = np.empty(n, np.int32)
    rc = np.empty(n, np.int32)
    link = np.zeros(n, np.bool_)
    edge = np.zeros(n, np.float64)
    left = np.zeros(n, np.float64)
    right = np.zeros(n, np.float64)
    tl = np.zeros(n + 1, np.int32)
    pos = np.empty(n, np.int32)
    lab = np.empty(n, np.int32)  # run labels (< period): eight to a vector in _confirmed_labels
    nx = np.empty(n, np.float64)
    nv = np.empty(n, np.float64)
    sm = np.empty((3, n), np.float64)
    marks = np.empty((3, n), np.int8)
    bounds = np.empty((2, n), np.int32)
    votes = np.zeros(max(n_copies, 1), np.int64)
    return rs, re, rc, link, edge, left, right, tl, pos, lab, nx, nv, sm, marks, bounds, votes


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def _row_votes(col, chain, y, tol, agree, disagree, npx, first, span):
    """Add the vertical agreement between rows y - 1 and y to the chains of row y - 1 (_label_row counted the
    chains of row y, their pixels and their votes against row y - 1, while writing them).

    Walks each chain's span with the counts in registers, then adds them once per chain: a per-pixel
    increment of a per-chain counter chains every pixel of a chain through memory."""
    if y == 0:
        return
    cy = y % chain.shape[0]  # (chain may hold the last rows only)
    cu = (y - 1) % chain.shape[0]
    tol32 = np.float32(tol)  # compared with float32 differences without a conversion per pixel
    for c in range(first[y - 1], first[y]):
        ag = 0
        dg = 0
        for xi in range(span[c, 0], span[c, 1] + 1):
            x = np.uint64(xi)  # unsigned: numba adds no negative-index fix per pixel (it made the loads gathers)
            pair = (chain[cu, x] == c) & (chain[cy, x] >= 0)
            close = abs(col[y - 1, x] - col[y, x]) <= tol32
            ag += pair & close
            dg += pair & (not close)
        agree[c] += ag
        disagree[c] += dg


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _drop_chains(y, col, chain, first, agree, disagree, npx, span, min_support):
    """vertical_check's verdict on the chains of row y, which have all their votes; returns how many it dropped."""
    cy = y % chain.shape[0]  # (chain may hold the last rows only)
    dropped = 0
    for c in range(first[y], first[y + 1]):
        if _unconfirmed(agree[c], disagree[c], npx[c], min_support):
            dropped += 1
            for x in range(span[c, 0], span[c, 1] + 1):
                if chain[cy, x] == c:
                    col[y, x] = np.nan
                    chain[cy, x] = -1
    return dropped


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _finish_row(
    y, col_e, chain_e, col_r, chain_r, first_e, first_r, agree_e, dis_e, npx_e, agree_r, dis_r, npx_r, check,
    min_support, cap, stats,
):  # fmt: skip
    """Row y has all its vertical votes: drop its unconfirmed chains, then merge runs into events (see merge_maps)."""
    W = col_e.shape[1]
    ce_y = y % chain_e.shape[0]  # (the chain maps may hold the last rows only)
    cr_y = y % chain_r.shape[0]
    if check:
        # a chain is dropped by marking its pixel count negative (read below)
        for c in range(first_e[y], first_e[y + 1]):
            if _unconfirmed(agree_e[c], dis_e[c], npx_e[c], min_support):
                npx_e[c] = -1
                stats[0] += 1
        for c in range(first_r[y], first_r[y + 1]):
            if _unconfirmed(agree_r[c], dis_r[c], npx_r[c], min_support):
                npx_r[c] = -1
                stats[1] += 1
    for x in range(W):
        ce = chain_e[ce_y, x]
        cr = chain_r[cr_y, x]
        ok_e = ce >= 0 and npx_e[ce] >= 0
        ok_r = cr >= 0 and npx_r[cr] >= 0
        if ok_e:
            if ok_r and abs(col_e[y, x] - col_r[y, x]) > 0.5:
                col_e[y, x] = np.nan
                chain_e[ce_y, x] = -1
                stats[3] += 1
        elif ok_r:
            col_e[y, x] = col_r[y, x]
            chain_e[ce_y, x] = cr + cap
            stats[2] += 1
        elif ce >= 0:
            col_e[y, x] = np.nan
            chain_e[ce_y, x] = -1


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def average_frames(a, b, out):
    """out = (a + b) // 2 element by element without overflow, for unsigned integer frames of one shape and
    dtype (the two-shot pair's texture): (a >> 1) + (b >> 1) + (a & b & 1) in one vectorised pass (numpy
    widened to uint32, added, divided and narrowed: four passes, ~1 ms for a 640x480 pair)."""
    fa = a.reshape(a.size)
    fb = b.reshape(b.size)
    fo = out.reshape(out.size)
    one = a.dtype.type(1)
    for i in range(fa.size):
        x = fa[i]
        y = fb[i]
        fo[i] = (x >> one) + (y >> one) + (x & y & one)
