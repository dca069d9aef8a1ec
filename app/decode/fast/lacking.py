"""Raw Bayer pairs (two-shot): the lacking channel's signs where its columns cannot resolve the stripes.

A Bayer sensor samples B (or R) in every other column, so its Nyquist period is 4 camera pixels; where a
projector stripe is narrower than 2 camera pixels a one-stripe B run is aliased, and the reconstruction's fill
(app/decode/mosaic.py) gives the columns lacking B the wrong sign of B's difference (docs/performance.md,
"Single-chip colour cameras"). G is sampled in every column, and the two-shot code flips one channel at each
stripe edge: inside a run of constant G sign every stripe edge flips B, so between two G edges (located at
full resolution) lie n stripes of equal width with B alternating. Per run: n is one more than the B sign
changes seen at the run's B columns, plus the pairs of changes they missed, from the run's length over the
local stripe width (the median of the neighbouring runs' lengths per seen stripe); the phase is the B
columns' vote, and the run is used only if every B column agrees with it, or all but one of three or more.

Where the fill's sign at a column lacking B disagrees, the pixel's B values are taken as swapped between the
two frames (the sign flips, the magnitude and the pair's mean stay). The fused decoder does that on its own
difference rows (lacking_row, from classify_row): the swapped pixel's differences are recomputed with the
same float32 operations as the row's, so the result is bit for bit that of swapping the frames' values first
(app/decode/mosaic_signs.py, the separate pass, kept as the reference the tests compare with).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import NO_LACKING, Classifier, ClassifyScratch, FrameTables, LackingScratch
from app.decode.fast.lacking_fill import model_sign_codes
from core.mosaic import CHANNEL, site_codes

G_STRONG = 0.05  # a G sign counts at |dG| of this share of its local maximum (three 8-pixel blocks)
WINDOW = 6  # runs either side whose widths per stripe give a run's local stripe width (their median)
GROUP = 4  # consecutive runs that share one such median (taken around the group's middle)
assert 2 * WINDOW + 1 == 13  # (the median's sorting network takes 13 values)
MIN_WIDTH = 1.0  # camera pixels per stripe the model accepts for a run
MAX_WIDTH = 3.2
# a run is used where its channel's columns agree with the model's alternation, all of them or all but
# MAX_DISSENT where there are at least MIN_VOTERS (docs/performance.md, "One dissenting column")
MAX_DISSENT = 1
MIN_VOTERS = 3


def lacking_channel(channels: str, mosaic: str | None) -> tuple[int, int, int]:
    """Classifier.lacking of a two-shot pattern's channels (e.g. "GB") seen through a raw mosaic: (pattern
    channel of G, camera channel of the other, column parity holding it); NO_LACKING without a mosaic or for
    patterns other than G and one other channel."""
    channels = str(channels).upper()
    if mosaic is None or len(channels) != 2 or "G" not in channels:
        return NO_LACKING
    ig = channels.index("G")
    cam = CHANNEL[channels[1 - ig]]
    codes = site_codes(mosaic)
    cx = 0 if (codes[0, 0] == cam or codes[1, 0] == cam) else 1
    return ig, int(cam), cx


@njit(cache=True, nogil=True, error_model="numpy")
def lacking_scratch(W: int) -> LackingScratch:
    """The buffers lacking_flips writes, for rows of W pixels."""
    return LackingScratch(
        np.zeros((W + 7) // 8 + 2, np.float32),
        np.zeros(W, np.int8),
        np.empty(W, np.float64),
        np.zeros(W + 1, np.int32),
        np.zeros(W + 1, np.int32),
        np.zeros(W + 1, np.int32),
        np.zeros(W, np.int32),
        np.empty(W, np.float64),
        np.empty(W, np.float64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.float64),
        np.empty(W, np.int64),
        np.empty(W, np.float64),
        np.empty(W, np.float32),
        np.empty(W, np.float32),
    )


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def lacking_row(
    f1: np.ndarray, f2: np.ndarray, y: int, tables: FrameTables, classifier: Classifier, scratch: ClassifyScratch
) -> int:
    """Row y's difference rows and noise floors (scratch.rows[0:4], as differences wrote them) with the lacking
    channel's values taken as swapped between the frames where the G edges say its sign is wrong, or moved
    apart where the swap keeps its unmixed sign (lacking_fill.model_sign_codes); no change without
    classifier.lacking. Returns the pixels changed (scratch.lacking.flips), their camera difference of the
    channel into scratch.lacking.flipped_c."""
    ig, cam, cx = classifier.lacking
    if cam < 0:
        return 0
    rows = scratch.rows
    s = scratch.lacking
    n = lacking_flips(rows[ig], rows[1 - ig], cx, s)
    lin = tables.lin
    dl = tables.dlin
    u = classifier.unmix
    u00, u01, u02, u10, u11, u12 = u[0, 0], u[0, 1], u[0, 2], u[1, 0], u[1, 1], u[1, 2]
    w00, w01, w02, w10, w11, w12 = abs(u00), abs(u01), abs(u02), abs(u10), abs(u11), abs(u12)
    ta = classifier.t_abs * np.float32(0.5)
    unmixed = u[1 - ig]
    inverse = tables.inverse
    a = f1[y]
    b = f2[y]
    fv0, fv1, nz0, nz1 = rows[0], rows[1], rows[2], rows[3]
    lacking = rows[1 - ig]
    for i in range(n):
        x = s.flips[i]
        # the lacking channel exchanged between the frames, or moved where the exchange keeps its unmixed sign
        # (lacking_fill); then the differences and noise floors in the order of the differences stage
        # (_row_differences, simd.differences16), so that the values are those of frames holding these codes
        a0, a1, a2 = a[x, 0], a[x, 1], a[x, 2]
        b0, b1, b2 = b[x, 0], b[x, 1], b[x, 2]
        if cam == 0:
            a0, b0 = b0, a0
        elif cam == 1:
            a1, b1 = b1, a1
        else:
            a2, b2 = b2, a2
        (a0, a1, a2), (b0, b1, b2) = model_sign_codes((a0, a1, a2), (b0, b1, b2), cam, unmixed, inverse, lacking[x])
        e0 = lin[0, b0] - lin[0, a0]
        e1 = lin[1, b1] - lin[1, a1]
        e2 = lin[2, b2] - lin[2, a2]
        n0 = dl[0, b0] + dl[0, a0]
        n1 = dl[1, b1] + dl[1, a1]
        n2 = dl[2, b2] + dl[2, a2]
        fv0[x] = u00 * e0 + u01 * e1 + u02 * e2
        fv1[x] = u10 * e0 + u11 * e1 + u12 * e2
        nz0[x] = ta * (w00 * n0 + w01 * n1 + w02 * n2)
        nz1[x] = ta * (w10 * n0 + w11 * n1 + w12 * n2)
        s.flipped_c[i] = e0 if cam == 0 else (e1 if cam == 1 else e2)
    return n


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def lacking_flips(g: np.ndarray, c: np.ndarray, cx: int, s: LackingScratch) -> int:
    """The pixels of one row whose lacking channel (differences c, held by the columns of parity cx; G's
    differences g) gets the other sign, into s.flips (each at most once, in increasing order); returns how
    many.

    Stripe edges fall every two or three pixels, so a branch per pixel or per run would be mispredicted about
    half the time: the edges and the runs are compacted by a store at every step and a count that advances by
    the condition, the medians are a sorting network and the flips a store per pixel of the channel's parity."""
    W = g.shape[0]
    nb = (W + 7) // 8
    bmax = s.g_max
    sg = s.sign
    edges = s.edges
    at = s.flips  # (the G edges' pixels first; the flips overwrite them once the edges are located)
    no_g, no_c, c_changes, c_sign = s.no_g, s.no_c, s.c_changes, s.c_sign
    r_e0, r_e1, r_x0, r_x1, r_s0, r_s1, r_n, ratio = s.e0, s.e1, s.x0, s.x1, s.s0, s.s1, s.changes, s.ratio
    r_scale = s.scale
    bmax[0] = 0.0
    bmax[nb + 1] = 0.0
    # whole blocks with loops of a fixed 8 (unrolled and vectorised), the last part-block after them
    full = W // 8
    for k in range(full):
        m = np.float32(0.0)
        for j in range(8):
            m = max(m, abs(g[8 * k + j]))
        bmax[k + 1] = m
    for k in range(full, nb):
        m = np.float32(0.0)
        for x in range(8 * k, W):
            m = max(m, abs(g[x]))
        bmax[k + 1] = m
    strong = np.float32(G_STRONG)
    for k in range(full):
        thr = _g_threshold(bmax[k], bmax[k + 1], bmax[k + 2], strong)
        for j in range(8):
            sg[8 * k + j] = _g_sign(g[8 * k + j], thr)
    for k in range(full, nb):
        thr = _g_threshold(bmax[k], bmax[k + 1], bmax[k + 2], strong)
        for x in range(8 * k, W):
            sg[x] = _g_sign(g[x], thr)
    zeros = 0
    for x in range(W):
        no_g[x] = zeros
        zeros += sg[x] == 0
    no_g[W] = zeros
    # the channel's columns: their signs (NaN and 0: none), and the counts the runs below read in one step each
    bad = 0
    changes = 0
    prev = 0
    for x in range(W):
        no_c[x] = bad
        c_changes[x] = changes
        if (x & 1) == cx:
            v = c[x]
            sign = 1 if v > 0 else -1
            bad += not (v > 0 or v < 0)
            changes += (prev != 0) & (sign != prev)
            prev = sign
            c_sign[x] = sign
    no_c[W] = bad
    c_changes[W] = changes
    ne = 0
    for x in range(W - 1):
        at[ne] = x
        ne += sg[x] * sg[x + 1] < 0
    for i in range(ne):
        x = at[i]
        edges[i] = x + g[x] / (g[x] - g[x + 1])
    # the runs of one G sign between consecutive edges that the model can use (every index read stays inside
    # the rows whatever the run, so the checks need no branch)
    nr = 0
    for i in range(ne - 1):
        e0 = edges[i]
        e1 = edges[i + 1]
        x0 = int(np.floor(e0)) + 1
        x1 = int(np.floor(e1))
        # the channel's columns from one pixel before the first G edge to one after the second (it is constant
        # across a G edge, so those see the run's end stripes)
        s0 = max(int(np.ceil(e0 - 1.0)), 0)
        s1 = min(int(np.floor(e1 + 1.0)), W - 1)
        s0 += (s0 & 1) != cx
        s1 -= (s1 & 1) != cx
        # one G sign throughout (no pixel without one: two opposite neighbours would be an edge between e0, e1),
        # and a sign at each of the channel's columns
        ok = (x1 >= x0) & (no_g[x1 + 1] == no_g[x0]) & (s1 >= s0 + 2) & (no_c[s1 + 1] == no_c[s0])
        r_e0[nr] = e0
        r_e1[nr] = e1
        r_x0[nr] = x0
        r_x1[nr] = x1
        r_s0[nr] = s0
        r_s1[nr] = s1
        flips = c_changes[s1 + 1] - c_changes[s0 + 1]  # (the changes from s0 to s1)
        r_n[nr] = flips
        ratio[nr] = (e1 - e0) / (flips + 1)
        nr += ok
    if nr == 0:
        return 0
    # per run, in loops over the runs (each a fixed sequence of operations: vectorised, gathers included): the
    # local stripe width (one median per group of runs), the stripe count n (into r_n) and n over the span
    w = 0.0
    for i in range(nr):
        if i % GROUP == 0:
            centre = min(i + GROUP // 2, nr - 1)
            w = _median13(ratio, max(0, centre - WINDOW), min(nr, centre + WINDOW + 1))
        span = r_e1[i] - r_e0[i]
        seen = r_n[i] + 1
        n = seen + 2 * max(0, int(np.round((span / w - seen) / 2.0)))
        r_n[i] = n
        r_scale[i] = n / span
    # per run, in one loop (its values stay in registers): the phase, the channel's columns' sign against the
    # model's alternation, used where all of them agree but at most `dissent` (each has a sign here, so the sum of
    # the agreements is their count less twice the dissenting ones, or minus that); then at the run's pixels
    # lacking the channel (the runs' pixel ranges are disjoint) whether the channel's sign differs from the model
    flip = sg  # (sg is free again)
    for x in range(W):
        flip[x] = 0
    for i in range(nr):
        e0, scale, n, s0, s1, x1 = r_e0[i], r_scale[i], r_n[i], r_s0[i], r_s1[i], r_x1[i]
        vote = 0
        for q in range(s0, s1 + 1, 2):
            vote += _alternating(q, e0, scale, n) * c_sign[q]
        width = (r_e1[i] - e0) / n
        voters = (s1 - s0) // 2 + 1
        dissent = MAX_DISSENT if voters >= MIN_VOTERS else 0
        use = (MIN_WIDTH <= width) & (width <= MAX_WIDTH) & (abs(vote) >= voters - 2 * dissent)
        phase = use * (1 if vote > 0 else -1)  # (0 for a run not used)
        first = r_x0[i] + ((r_x0[i] & 1) == cx)
        for q in range(first, x1 + 1, 2):
            flip[q] = _disagrees(q, c, W, phase, e0, scale, n)
    n_flip = 0
    for x in range(1 - cx, W, 2):
        at[n_flip] = x
        n_flip += flip[x]
    return n_flip


@njit(inline="always")
def _disagrees(q, c, W, phase, e0, scale, n):
    """Whether the channel's sign at column q (read inside the row) differs from a run's model (phase 0: the
    run is not used, no)."""
    p = phase * _alternating(q, e0, scale, n)
    v = c[min(q, W - 1)]
    agrees = ((p > 0) & (v > 0)) | ((p < 0) & (v < 0))  # (NaN: neither)
    return (p != 0) & (not agrees)


@njit(inline="always")
def _g_threshold(b0, b1, b2, strong):
    """The |dG| a G sign needs beside three block maxima: +inf in an unlit block (so no sign there, without a
    select per pixel)."""
    loc = max(b0, max(b1, b2))
    return strong * loc if loc > 0 else np.float32(np.inf)


@njit(inline="always")
def _g_sign(v, thr):
    """G's sign where |v| reaches thr, else 0 (int8; arithmetic, not a select of int8 values, which LLVM
    vectorises poorly)."""
    return (np.int8(v > 0) - np.int8(v < 0)) * np.int8(abs(v) >= thr)


@njit(inline="always")
def _cas(a, b):
    return min(a, b), max(a, b)


@njit(inline="always")
def _median13(v, lo, hi):
    """The median of v[lo:hi], hi - lo <= 13 (the mean of the middle two for an even count): the window padded
    with +inf to 13 values and sorted by a network of 48 compare-exchanges (Batcher's odd-even merge sort of 16,
    less the comparators with the padding's last three, which never move), branch-free and in registers."""
    m = hi - lo
    last = v.shape[0] - 1
    v0, v1, v2, v3 = _pad(v, lo, m, 0, last), _pad(v, lo, m, 1, last), _pad(v, lo, m, 2, last), _pad(v, lo, m, 3, last)
    v4, v5, v6, v7 = _pad(v, lo, m, 4, last), _pad(v, lo, m, 5, last), _pad(v, lo, m, 6, last), _pad(v, lo, m, 7, last)
    v8, v9, v10 = _pad(v, lo, m, 8, last), _pad(v, lo, m, 9, last), _pad(v, lo, m, 10, last)
    v11, v12 = _pad(v, lo, m, 11, last), _pad(v, lo, m, 12, last)
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
    k = m // 2
    upper = _pick(k, v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12)
    lower = _pick(k - 1, v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12)
    return upper if m & 1 else 0.5 * (lower + upper)


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


@njit(inline="always")
def _alternating(x, e0, scale, n):
    """+1 or -1 by the parity of the stripe of n equal ones from e0 (scale: n over their span) that holds pixel
    x."""
    j = min(int(max((x - e0) * scale, 0.0)), n - 1)
    return 1 - 2 * (j & 1)
