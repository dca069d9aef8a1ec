"""Per-pixel classification (paper section 4): a pixel's stripe code from its differences or colour.

Two-shot: code bit c is set where pattern channel c was at max in frame 1 (d = frame2 - frame1 < 0). A sign
counts only above the noise floor and above t_rel times the channel's local amplitude (max |d| over a block and
its two neighbours), so coloured surfaces keep their codes while stripe edges and shadows give none. One-shot:
the index of the brightest stripe colour, when clearly brighter than the second. `twoshot_classify` and
`oneshot_classify` classify whole images; `classify_row` is the fused decoder's per-row form of the former.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import Classifier, ClassifyScratch, FrameTables
from app.decode.fast.differences import differences
from app.decode.fast.lacking import lacking_row, lacking_scratch
from app.decode.fast.lacking_leak import leak_row
from app.decode.simd import spread8x2


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


@njit(cache=True, nogil=True, inline="always")
def _pixel_differences(f1, f2, y, x, lin, dlin):
    """Pixel (y, x)'s linear frame2 - frame1 per camera channel and the summed noise slopes of both values."""
    a0 = f1[y, x, 0]
    a1 = f1[y, x, 1]
    a2 = f1[y, x, 2]
    b0 = f2[y, x, 0]
    b1 = f2[y, x, 1]
    b2 = f2[y, x, 2]
    d = (lin[0, b0] - lin[0, a0], lin[1, b1] - lin[1, a1], lin[2, b2] - lin[2, a2])
    n = (dlin[0, b0] + dlin[0, a0], dlin[1, b1] + dlin[1, a1], dlin[2, b2] + dlin[2, a2])
    return d, n


@njit(cache=True, nogil=True, error_model="numpy")
def twoshot_classify(
    f1: np.ndarray,
    f2: np.ndarray,
    lin: np.ndarray,
    dlin: np.ndarray,
    unmix: np.ndarray,
    t_abs: np.float32,
    t_rel: np.float32,
    t_rel_edge: np.float32,
    block: int,
    code: np.ndarray,
    feat: np.ndarray,
    noise: np.ndarray,
) -> None:
    """code[y, x] = bits (1 = channel max in frame 1, i.e. frame2 - frame1 < 0), -1 when unsure.

    Raw values are linearised through lin (3, L) (the camera response), then feat[y, x, c] =
    unmixed linear frame2 - frame1 of pattern channel c. A sign counts only when |d| is above the
    noise floor (t_abs raw 8-bit DN carried through the response slope dlin: noise[y, x, c]) and
    above t_rel times the channel's local amplitude (max |d| over about 3 blocks), so coloured
    surfaces (small amplitude in one channel) keep their codes while stripe edges (d crossing
    zero) and shadows (no amplitude) give no code. noise[y, x, c] ends as the zero-crossing sign threshold.
    """
    H, W = code.shape
    m = unmix.shape[0]
    nb = (W + block - 1) // block
    bmax = np.empty((m, nb), np.float32)
    bmin = np.empty(nb, np.float32)
    for y in range(H):
        for x in range(W):
            (d0, d1, d2), (n0, n1, n2) = _pixel_differences(f1, f2, y, x, lin, dlin)
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
def oneshot_classify(
    img: np.ndarray,
    unmix: np.ndarray,
    colour_rows: np.ndarray,
    t_abs: np.float32,
    t_margin: np.float32,
    block: int,
    use_hue: bool,
    code: np.ndarray,
    feat: np.ndarray,
) -> None:
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
def classify_scratch(m: int, W: int, block: int) -> ClassifyScratch:
    """The buffers classify_row writes, for m pattern channels and rows of W pixels."""
    nb = (W + block - 1) // block
    return ClassifyScratch(
        np.empty((2 * m, W), np.float32),
        np.empty((max(m, 2), nb + 2), np.float32),
        np.empty((2, nb + 2), np.float32),
        np.empty((2, W), np.float32),
        np.empty(W, np.int8),
        lacking_scratch(W),
    )


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def classify_row(
    f1: np.ndarray,
    f2: np.ndarray,
    y: int,
    tables: FrameTables,
    classifier: Classifier,
    scratch: ClassifyScratch,
    want_thr: bool,
    ahead: tuple,
) -> None:
    """twoshot_classify for row y of the frames: codes into scratch.code, the unmixed differences into
    scratch.rows[0:m] and, with want_thr, the zero-crossing sign thresholds into scratch.rows[m:2m]. ahead: rows
    to prefetch meanwhile (see differences). Frames reconstructed from a raw mosaic (classifier.lacking) get the
    lacking channel's signs from the G edges on the difference rows (lacking.lacking_row), and its leak into G
    removed at its stripes' amplitude (lacking_leak.leak_row).

    The same arithmetic in simple loops (differences and noise floors, block maxima, thresholds), each reading
    plain rows and writing one kind of array, so that each is vectorised; the coefficients live in locals
    (float32 outputs may alias the float32 tables, which would otherwise be reloaded after every store). Written
    out for the usual two pattern channels; other channel counts take _classify_row_any.
    """
    if classifier.unmix.shape[0] != 2:
        _classify_row_any(f1, f2, y, tables, classifier, scratch)
        return
    t_abs, t_rel, t_rel_edge, block = classifier.t_abs, classifier.t_rel, classifier.t_rel_edge, classifier.block
    code = scratch.code
    W = code.shape[0]
    nb = (W + block - 1) // block
    if scratch.block_max.shape[1] < nb + 2 or scratch.block_thr.shape[1] < nb + 2:
        raise ValueError("classify_row: block buffers need nb + 2 entries")
    ta = t_abs * np.float32(0.5)
    rows = scratch.rows
    fv0 = rows[0]
    fv1 = rows[1]
    nz0 = rows[2]
    nz1 = rows[3]
    differences(f1, f2, y, tables.lin, tables.dlin, tables.packed, classifier.unmix, ta, rows, ahead)
    flips = lacking_row(f1, f2, y, tables, classifier, scratch)  # (a raw mosaic's aliased signs; else nothing)
    leak_row(f1, f2, y, tables, classifier, scratch, flips)  # (and its leak into G; else nothing)
    # block maxima of |d| at bm[1 + b], with zero guards at both ends
    bm0 = scratch.block_max[0]
    bm1 = scratch.block_max[1]
    bm0[0] = 0.0
    bm1[0] = 0.0
    bm0[nb + 1] = 0.0
    bm1[nb + 1] = 0.0
    # whole blocks of the usual 8 pixels written out (no loop of unknown length per block); the rest in the loop
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
    # the code threshold t_rel * (max |d| over a block and its two neighbours) per block, then spread over the
    # block's pixels, so that the per-pixel loop below reads plain rows (a block index per pixel keeps it
    # scalar); whole pairs of 8-pixel blocks with one 16-lane store each, the rest in the loop
    q0 = scratch.pixel_thr[0]
    q1 = scratch.pixel_thr[1]
    tb0 = scratch.block_thr[0]
    tb1 = scratch.block_thr[1]
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
        # bitwise & and a select: no branch per pixel (signs flip every few pixels)
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
                nz0[x] = max(te0, nz0[x])  # the noise floor raised to the zero-crossing sign threshold
                nz1[x] = max(te1, nz1[x])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _classify_row_any(f1, f2, y, tables, classifier, scratch):
    """classify_row for any number of pattern channels (its thresholds are always written)."""
    lin, dlin = tables.lin, tables.dlin
    unmix, t_abs, t_rel, block = classifier.unmix, classifier.t_abs, classifier.t_rel, classifier.block
    t_rel_edge = classifier.t_rel_edge
    tmp = scratch.rows
    bmax = scratch.block_max
    code = scratch.code
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
                (d0, d1, d2), (n0, n1, n2) = _pixel_differences(f1, f2, y, x, lin, dlin)
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
                if not abs(d) >= thr:  # (NaN: no sign, as in classify_row and the numpy reference)
                    cd = -1
                elif d < 0 and cd >= 0:
                    cd |= bit
                code[x] = cd
                tmp[m + c, x] = te if te > nz else nz  # the zero-crossing segmentation's threshold
            prev = cur
            cur = nxt
