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
from app.decode.fast.bundles import (
    NO_LACKING,
    ChannelColumns,
    Classifier,
    ClassifyScratch,
    FrameTables,
    LackingScratch,
)
from app.decode.fast.lacking_fill import exchanged, model_sign_codes
from app.decode.fast.median13 import median13, network13
from app.decode.primitives import append_where, gather
from core.mosaic import CHANNEL, site_codes

# a G sign counts where |dG| reaches this share of its local maximum (three 8-pixel blocks) and the noise floor
# of dG (the decoder's, rows[2:4]): the floor, not a larger share, keeps noise out of weakly lit patches, whose
# stripes a larger share would lose (docs/performance.md, "G's sign above its noise floor")
G_STRONG = 0.02
# runs either side whose widths per stripe give a run's local stripe width (their median, per run: where the width
# changes fast, on a turned-away surface, a wider window or one median per group of runs overestimates it and
# miscounts the stripes; docs/performance.md, "The local width per run")
WINDOW = 5
assert WINDOW == 5  # (_stripe_counts reads a whole window of 11 runs at fixed offsets into the 13-value network)
MIN_WIDTH = 1.0  # camera pixels per stripe the model accepts for a run
MAX_WIDTH = 3.2
# a run is used where its channel's columns agree with the model's alternation, all of them or all but
# MAX_DISSENT where there are at least MIN_VOTERS (docs/performance.md, "One dissenting column")
MAX_DISSENT = 1
MIN_VOTERS = 3
# a run the model refuses takes its neighbours' phase where the local stripe width (camera pixels) is in this range
CARRY_WIDTHS = (1.75, 2.2)
CARRY_AGREEMENT = 0.2  # and where its stripe width is within this share of the width of each run it takes it from
SPAN = 16  # columns of one parity a word of bits covers (a run of more is checked in a loop of its own)


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
    P = W + 24  # (per pixel, event or run, with room for the padding to whole vectors and compressed stores)
    H = W // 2 + 4 * SPAN  # (per column of one parity, with room for the columns read on from any)
    i8 = np.int8
    i32 = np.int32
    f32 = np.float32
    f64 = np.float64
    columns = ChannelColumns(
        np.zeros(H, i32),  # sign
        np.zeros(H, i32),  # no_sign
        np.zeros(H, i32),  # words
        np.zeros(H, i32),  # sign_bits
        np.zeros(H, i32),  # lacking_sign
        np.zeros(H, i32),  # lacking_bits
        np.zeros(H, i32),  # spare
    )
    return LackingScratch(
        np.zeros((W + 7) // 8 + 2, f32),  # g_max
        np.zeros(P, f32),  # g_threshold
        np.zeros(W, i8),  # sign
        np.zeros(P, i32),  # strong
        np.zeros(P, i8),  # event
        np.zeros(P, i32),  # event_pixel
        np.zeros(P, i32),  # is_edge
        np.zeros(P, f32),  # g_at
        np.zeros(P, f32),  # g_next
        np.zeros(P, f64),  # event_position
        np.zeros(P, i32),  # first_column
        np.zeros(P, i32),  # column_span
        np.zeros(P, i32),  # first_word
        np.zeros(P, i32),  # candidate_changes
        np.zeros(P, f64),  # candidate_ratio
        np.zeros(P, i8),  # candidate
        np.zeros(P, i8),  # usable
        np.zeros(P, i8),  # long_candidate
        np.zeros(P, i32),  # long_candidates
        np.zeros(P, i32),  # run_event
        np.zeros(P, i32),  # run_first_column
        np.zeros(P, i32),  # run_changes
        np.zeros(P, f64),  # run_e0
        np.zeros(P, f64),  # run_e1
        np.zeros(P, f64),  # run_ratio
        np.zeros(P, f64),  # local_width
        np.zeros(P, np.int64),  # run_stripes
        np.zeros(P, f64),  # run_scale
        np.zeros(P, i32),  # held_bits
        np.zeros(P, i32),  # lacking_bits
        np.zeros(P, i32),  # votes
        np.zeros(P, i32),  # flip_masks
        np.zeros(P, i8),  # long_run
        np.zeros(P, i8),  # emit
        np.zeros(P, i32),  # emitted
        np.zeros(P, i32),  # long_runs
        np.zeros(P, i32),  # own_phase
        np.zeros(P, i32),  # run_phase
        np.zeros(P, i8),  # refused
        np.zeros(P, i32),  # refused_runs
        columns,
        np.zeros(P, np.int64),  # flips
        np.empty(W, f32),  # camera_c
        np.empty(W, f32),  # flipped_c
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
    n = lacking_flips(rows[ig], rows[1 - ig], rows[2 + ig], cx, s)
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
        swapped = exchanged((a[x, 0], a[x, 1], a[x, 2]), (b[x, 0], b[x, 1], b[x, 2]), cam)
        (a0, a1, a2), (b0, b1, b2) = model_sign_codes(*swapped, cam, unmixed, inverse, lacking[x])
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
def lacking_flips(g: np.ndarray, c: np.ndarray, g_floor: np.ndarray, cx: int, s: LackingScratch) -> int:
    """The pixels of one row whose lacking channel (differences c, held by the columns of parity cx; G's
    differences g, their noise floor g_floor) gets the other sign, into s.flips (each at most once, in
    increasing order); returns how many.

    Stripe edges fall every two or three pixels, so a branch per pixel or per run would be mispredicted about
    half the time, and a loop that reads at computed indices beside its stores stays scalar: every stage is a
    loop of a fixed sequence of operations per pixel, column, event or run over plain rows (vectorised), the
    values a stage reads at computed indices are gathered into rows before it (primitives.gather), the events
    and the runs are compacted by compressed stores (append_where), the medians are a sorting network, and a
    run's columns are taken as words of bits, sixteen (its checks) or eight (its vote and flips) at a time (the
    few longer runs finish in loops over them alone)."""
    W = g.shape[0]
    if W < 2:
        return 0
    _g_signs(g, g_floor, s.g_max, s.g_threshold, s.sign)
    _channel_columns(c, cx, s.columns)
    ne = _events(g, s)
    nr = _runs(s, ne, cx, W)
    if nr == 0:
        return 0
    _stripe_counts(s, nr)
    return _flips(s, nr, cx, W)


@njit(inline="always")
def _g_signs(g, floor, bmax, thr, sg):
    """sg: G's strong signs, from the maxima of |dG| per block of 8 (into bmax, at 1 + b with zero guards), their
    thresholds per pixel (thr, 8 per block) and G's noise floor per pixel (floor)."""
    W = g.shape[0]
    nb = (W + 7) // 8
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
    # each block's threshold spread over its pixels, then the signs in one loop over the pixels
    strong = np.float32(G_STRONG)
    for k in range(nb):
        t = _g_threshold(bmax[k], bmax[k + 1], bmax[k + 2], strong)
        for j in range(8):
            thr[8 * k + j] = t
    for x in range(W):
        sg[x] = _g_sign(g[x], max(thr[x], floor[x]))


@njit(inline="always")
def _channel_columns(c, cx, cols):
    """Per column holding the channel (index k: column 2k + cx): its sign (+1, else -1: NaN and 0 too), whether
    it has none (NaN, 0), the bits m < 8 of whether column k + m's sign is +1, and the word of SPAN bits m of
    whether column k + m has no sign, with at SPAN + m whether k + m's sign differs from k + m - 1's. Per
    column lacking it (index l: column 2l + 1 - cx): its sign (0 for NaN and 0) and the bits m of whether c is
    > 0 at column l + m, and at 8 + m whether it is < 0."""
    c_sign, no_c, words, c_bits, l_sign, l_bits, spare = cols  # (ChannelColumns)
    W = c.shape[0]
    nk = (W - cx + 1) // 2
    nl = (W - (1 - cx) + 1) // 2
    # (pairs of columns in one loop: both values read as the interleaved pair, each stored to its own row)
    for k in range(W // 2):
        a = c[2 * k]
        b = c[2 * k + 1]
        v = b if cx else a
        u = a if cx else b
        c_sign[k] = np.int32(1) if v > 0 else np.int32(-1)
        no_c[k] = np.int32(not ((v > 0) | (v < 0)))
        l_sign[k] = np.int32(u > 0) - np.int32(u < 0)
    if W & 1:  # (the last column, even)
        v = c[W - 1]
        if cx == 0:
            c_sign[nk - 1] = np.int32(1) if v > 0 else np.int32(-1)
            no_c[nk - 1] = np.int32(not ((v > 0) | (v < 0)))
        else:
            l_sign[nl - 1] = np.int32(v > 0) - np.int32(v < 0)
    for k in range(nk, nk + 3 * SPAN):
        c_sign[k] = -1
        no_c[k] = 0
    for k in range(nl, nl + 3 * SPAN):
        l_sign[k] = 0
    # the words by doubling: after the step of d, bit m of entry k holds column k + m for m < 2d (each step over
    # every entry the later steps read, so that none is left from an earlier row)
    words[0] = no_c[0]
    for k in range(1, nk + 2 * SPAN):
        words[k] = no_c[k] | (np.int32((c_sign[k] != c_sign[k - 1]) & (k < nk)) << np.int32(SPAN))
    src, dst = words, spare
    d = 1
    while d < SPAN:
        for k in range(nk + SPAN):
            dst[k] = src[k] | (src[k + d] << np.int32(d))
        src, dst = dst, src
        d *= 2
    for k in range(nk + 1):
        bits = np.int32(0)
        for m in range(8):
            bits |= np.int32(c_sign[k + m] > 0) << np.int32(m)
        c_bits[k] = bits
    for k in range(nl + 1):
        bits = np.int32(0)
        for m in range(8):
            v = l_sign[k + m]
            bits |= (np.int32(v > 0) << np.int32(m)) | (np.int32(v < 0) << np.int32(8 + m))
        l_bits[k] = bits


@njit(inline="always")
def _whole(n):
    """n rounded up to whole vectors of 8 (the loops over events and runs run on over padding of valid
    indices, so they have no scalar remainder)."""
    return (n + 7) & ~7


@njit(inline="always")
def _events(g, s):
    """The events of the row: the G edges (opposite strong signs at x and x + 1) and the pixels without a strong
    G sign, compacted into s.event_pixel (their pixel), with whether each is an edge (s.is_edge) and its
    position (s.event_position: the edge's zero crossing, a pixel without a sign its own pixel). A run of one G
    sign is a pair of consecutive events that are both edges. Returns how many."""
    sg, ev = s.sign, s.event
    at, strong, is_edge = s.event_pixel, s.strong, s.is_edge
    epos = s.event_position
    gx, gx1 = s.g_at, s.g_next
    W = g.shape[0]
    for x in range(W - 1):
        a = sg[x]
        b = sg[x + 1]
        ev[x] = (a == 0) | ((b != 0) & (a != b))
    for x in range(W):
        strong[x] = sg[x] != 0
    ne = append_where(ev, W - 1, at)
    pad = _whole(ne) + 8
    for j in range(ne, pad):
        at[j] = 0
    gather(gx, g, at, pad)
    gather(gx1, g[1:], at, pad)
    gather(is_edge, strong, at, pad)
    for j in range(ne, pad):
        is_edge[j] = 0
    for j in range(pad):
        # (the expression of the differences' zero crossing, in its types: float32, then float64)
        epos[j] = at[j] + gx[j] / (gx[j] - gx1[j]) if is_edge[j] != 0 else np.float64(at[j])
    return ne


@njit(inline="always")
def _run_bounds(e0, e1, cx, W):
    """A run's first and last pixel (x0, x1) and the indices (k0, k1) of the first and last column holding the
    channel from one pixel before its first edge e0 to one after its second e1 (it is constant across a G edge,
    so those see the run's end stripes); every index stays inside the row whatever e0 <= e1 in [0, W - 1)."""
    x0 = int(np.floor(e0)) + 1
    x1 = int(np.floor(e1))
    s0 = max(int(np.ceil(e0 - 1.0)), 0)
    s1 = min(int(np.floor(e1 + 1.0)), W - 1)
    s0 += (s0 & 1) != cx
    s1 -= (s1 & 1) != cx
    return x0, x1, (s0 - cx) >> 1, (s1 - cx) >> 1


@njit(inline="always")
def _runs(s, ne, cx, W):
    """The runs of one G sign between consecutive events that the model can use (one G sign throughout, and a
    sign at each of its three or more columns holding the channel): per run its first event (s.run_event), its
    edges (s.run_e0, s.run_e1), the sign changes its columns see (s.run_changes) and its length per seen
    stripe (s.run_ratio). Returns how many."""
    cols = s.columns
    c_sign, no_c, words = cols.sign, cols.no_sign, cols.words  # (four doublings end in the row they start in)
    is_edge, k0s, spans, w0 = s.is_edge, s.first_column, s.column_span, s.first_word
    cand_changes, long_pairs = s.candidate_changes, s.long_candidates
    run, changes = s.run_event, s.run_changes
    epos, cand_ratio, ratio, e0s, e1s = s.event_position, s.candidate_ratio, s.run_ratio, s.run_e0, s.run_e1
    pre, ok, long = s.candidate, s.usable, s.long_candidate
    nc = ne - 1
    whole = _whole(max(nc, 0))
    for j in range(whole):
        e0 = epos[j]
        e1 = epos[j + 1]
        x0, x1, k0, k1 = _run_bounds(e0, e1, cx, W)
        k0s[j] = k0
        spans[j] = k1 - k0 + 1
        pre[j] = (is_edge[j] != 0) & (is_edge[j + 1] != 0) & (x1 >= x0) & (k1 >= k0 + 1)
    # the pair's columns k0 .. k1 from the word at k0 (those of more than SPAN columns in a loop of their own)
    gather(w0, words, k0s, whole)
    for j in range(whole):
        span = spans[j]
        cut = min(max(span, 0), SPAN)
        w = w0[j]
        flips = _bit_count16((w >> np.int32(SPAN + 1)) & ((np.int32(1) << np.int32(max(cut - 1, 0))) - np.int32(1)))
        ok[j] = pre[j] & ((w & ((np.int32(1) << np.int32(cut)) - np.int32(1))) == 0)
        long[j] = pre[j] & (span > SPAN)
        cand_changes[j] = flips
        cand_ratio[j] = (epos[j + 1] - epos[j]) / (flips + 1)
    n_long = append_where(long, nc, long_pairs) if nc > 0 else 0
    for t in range(n_long):
        j = long_pairs[t]
        k0 = k0s[j]
        k1 = k0 + spans[j] - 1
        bad = 0
        flips = 0
        for k in range(k0, k1 + 1):
            bad += no_c[k]
            flips += (k > k0) & (c_sign[k] != c_sign[k - 1])
        ok[j] = bad == 0
        cand_changes[j] = flips
        cand_ratio[j] = (epos[j + 1] - epos[j]) / (flips + 1)
    nr = append_where(ok, nc, run) if nc > 0 else 0
    pad = _whole(nr) + 8
    for i in range(nr, pad):
        run[i] = 0
    gather(ratio, cand_ratio, run, pad)
    gather(changes, cand_changes, run, pad)
    gather(e0s, epos, run, pad)
    gather(e1s, epos[1:], run, pad)
    # per run the sign bits of its first eight columns of either kind (_channel_columns), from its first, k0
    k0r, held, lacking = s.run_first_column, s.held_bits, s.lacking_bits
    gather(k0r, k0s, run, pad)
    gather(held, cols.sign_bits, k0r, pad)
    gather(lacking, cols.lacking_bits[cx:], k0r, pad)
    return nr


@njit(inline="always")
def _stripe_counts(s, nr):
    """Per run the local stripe width (the median of the ratios of the runs within WINDOW of it: s.local_width),
    its stripe count n (the changes seen, plus the pairs of them missed: s.run_stripes), n over its span
    (s.run_scale)."""
    ratio, e0s, e1s, wr, scale = s.run_ratio, s.run_e0, s.run_e1, s.local_width, s.run_scale
    changes, r_n = s.run_changes, s.run_stripes
    inf = np.inf
    # runs whose window is whole (2 WINDOW + 1 runs) read it at fixed offsets, padded to the network's 13 with
    # +inf (sorted last: the median stays the middle value of the window's own); the runs near the ends after
    head = min(WINDOW, nr)
    for i in range(head):
        wr[i] = _median(ratio, i, nr)
    for i in range(WINDOW, nr - WINDOW):
        b = i - WINDOW
        wr[i] = network13(
            ratio[b],
            ratio[b + 1],
            ratio[b + 2],
            ratio[b + 3],
            ratio[b + 4],
            ratio[b + 5],
            ratio[b + 6],
            ratio[b + 7],
            ratio[b + 8],
            ratio[b + 9],
            ratio[b + 10],
            inf,
            inf,
        )[WINDOW]
    for i in range(max(nr - WINDOW, head), nr):
        wr[i] = _median(ratio, i, nr)
    for i in range(nr, _whole(nr)):
        wr[i] = 1.0  # (the padding's runs: any finite width)
    for i in range(_whole(nr)):
        span = e1s[i] - e0s[i]
        seen = np.int64(changes[i]) + 1
        n = seen + 2 * max(0, int(np.round((span / wr[i] - seen) / 2.0)))
        r_n[i] = n
        scale[i] = n / span


@njit(inline="always")
def _median(ratio, i, nr):
    """The local stripe width of run i: the median of the ratios of the runs within WINDOW of it."""
    return median13(ratio, max(0, i - WINDOW), min(nr, i + WINDOW + 1))


@njit(inline="always")
def _flips(s, nr, cx, W):
    """Per run the phase, the channel's columns' sign against the model's alternation, used where all of them
    agree but at most `dissent` (_phase), else carried across a G edge from the runs beside it (_carried); then at
    the run's pixels lacking the channel (the runs' pixel ranges are disjoint and increasing) whether the
    channel's sign differs from the model: into s.flips. A run's columns from its first holding the channel, s0,
    alternate: those holding it at s0 + 2m, those lacking it at s0 + 1 + 2m (the first at or after its first
    pixel). Runs of at most eight of each (all but a few in a hundred) are taken in one loop, as words of bits
    m; the others, and the runs refused, in loops over them alone."""
    e0s, e1s, scale = s.run_e0, s.run_e1, s.run_scale
    held, lacking, masks, votes = s.held_bits, s.lacking_bits, s.flip_masks, s.votes
    r_n = s.run_stripes
    is_long, emit, emitted, longs = s.long_run, s.emit, s.emitted, s.long_runs
    own, phase, refused = s.own_phase, s.run_phase, s.refused
    wr = s.local_width
    for i in range(_whole(nr)):
        e0 = e0s[i]
        e1 = e1s[i]
        _, x1, k0, k1 = _run_bounds(e0, e1, cx, W)
        sc, n = scale[i], r_n[i]
        top = np.float64(n - 1)
        s0 = np.float64(2 * k0 + cx)
        odd_held = np.int32(0)  # (bit m: the model's stripe at s0 + 2m is odd, its sign -1)
        odd_lacking = np.int32(0)  # (at s0 + 1 + 2m)
        for m in range(8):
            odd_held |= _odd(s0 + 2 * m, e0, sc, top) << np.int32(m)
            odd_lacking |= _odd(s0 + (2 * m + 1), e0, sc, top) << np.int32(m)
        voters = k1 - k0 + 1
        lacking_n = _lacking_count(x1, k0, cx)
        long = (voters > 8) | (lacking_n > 8)
        # the vote: agreeing columns count +1 (the channel's sign bit is set where the model's stripe is even)
        agree = (odd_held ^ held[i]) & ((np.int32(1) << np.int32(min(voters, 8))) - np.int32(1))
        vote = 2 * _bit_count8(agree) - min(voters, 8)
        p = _phase(vote, voters, (e1 - e0) / n)  # (a long run's from its whole vote, below)
        bits = _lacking_bits(odd_lacking, p, lacking[i], lacking_n)
        masks[i] = bits | (odd_lacking << np.int32(8))
        votes[i] = vote
        own[i] = p
        is_long[i] = long
        refused[i] = _may_carry(p, wr[i])
        emit[i] = (bits != 0) | long
    c_sign = s.columns.sign
    n_long = append_where(is_long, nr, longs)
    for t in range(n_long):  # (more than eight columns of either kind: the vote completed over the rest)
        i = longs[t]
        e0 = e0s[i]
        _, x1, k0, k1 = _run_bounds(e0, e1s[i], cx, W)
        vote = np.int64(votes[i])
        for k in range(k0 + 8, k1 + 1):
            vote += _alternating(2 * k + cx, e0, scale[i], r_n[i]) * c_sign[k]
        p = _phase(vote, k1 - k0 + 1, _run_width(s, i))
        votes[i] = vote
        own[i] = p
        phase[i] = p
        refused[i] = _may_carry(p, wr[i])
        bits = _lacking_bits(masks[i] >> np.int32(8), p, lacking[i], _lacking_count(x1, k0, cx))
        masks[i] = bits | (masks[i] & np.int32(0xFF00))
    _carried(s, nr, cx, W)
    l_sign = s.columns.lacking_sign
    flips = s.flips
    n_flip = 0
    n_emit = append_where(emit, nr, emitted)
    for t in range(n_emit):
        i = emitted[t]
        e0 = e0s[i]
        _, x1, k0, _ = _run_bounds(e0, e1s[i], cx, W)
        first = 2 * k0 + cx + 1
        bits = masks[i] & np.int32(255)
        for m in range(8):
            flips[n_flip] = first + 2 * m
            n_flip += (bits >> m) & 1
        p_run = phase[i]  # (written for the long runs and the carried ones: the only ones it is read for)
        for q in range(first + 16, x1 + 1, 2):  # (none unless long)
            p = p_run * _alternating(q, e0, scale[i], r_n[i])
            flips[n_flip] = q
            n_flip += (p != 0) & (p != l_sign[q >> 1])
    return n_flip


@njit(inline="always")
def _carried(s, nr, cx, W):
    """The runs without a phase of their own where the local stripe width lies in CARRY_WIDTHS (s.refused) take the
    phase carried across the G edge they share with a run beside it that has one, with its flip mask and whether
    it is emitted. The two-shot code flips one channel at each stripe edge, so the lacking channel is constant
    across a G edge: the last stripe of a run of n stripes and phase p has the sign p (-1)^(n - 1), which is the
    next run's first. CARRY_WIDTHS is where the channel's own columns sit at their Nyquist limit (such a run was
    refused for their dissent; wider stripes are refused for a stripe count the columns saw right). Carried where
    the two sides agree or one is known, the run's own vote is not against it, and its stripes are as wide as
    those of each run it takes the phase from, to CARRY_AGREEMENT (a stripe count off by two, under a phase
    carried in, would flip the wrong columns) (docs/performance.md, "The phase across a G edge")."""
    own, phase, refused, runs = s.own_phase, s.run_phase, s.refused, s.refused_runs
    event, r_n, votes = s.run_event, s.run_stripes, s.votes
    masks, emit, lacking = s.flip_masks, s.emit, s.lacking_bits
    n_refused = append_where(refused, nr, runs)
    for t in range(n_refused):
        i = runs[t]
        width = _run_width(s, i)
        p = 0
        agree = True
        if i > 0 and event[i - 1] + 1 == event[i] and own[i - 1] != 0:  # (the run before ends where this one starts)
            p = own[i - 1] * _carry_sign(r_n[i - 1])
            left = _run_width(s, i - 1)
            agree = abs(width - left) <= CARRY_AGREEMENT * left
        if i + 1 < nr and event[i] + 1 == event[i + 1] and own[i + 1] != 0:
            q = own[i + 1] * _carry_sign(r_n[i])
            right = _run_width(s, i + 1)
            agree &= (p == 0) | (p == q)
            agree &= abs(width - right) <= CARRY_AGREEMENT * right
            p = q
        if p == 0 or not agree or p * votes[i] < 0 or width < MIN_WIDTH or width > MAX_WIDTH:
            continue
        _, x1, k0, _ = _run_bounds(s.run_e0[i], s.run_e1[i], cx, W)
        bits = _lacking_bits(masks[i] >> np.int32(8), p, lacking[i], _lacking_count(x1, k0, cx))
        masks[i] |= bits
        phase[i] = p
        emit[i] |= bits != 0


@njit(inline="always")
def _may_carry(p, local_width):
    """Whether a run with own phase p and this local stripe width is one _carried may give a phase: none of its
    own, and the width in CARRY_WIDTHS."""
    return (p == 0) & (CARRY_WIDTHS[0] <= local_width) & (local_width <= CARRY_WIDTHS[1])


@njit(inline="always")
def _run_width(s, i):
    """Run i's stripe width: its span over its stripe count."""
    return (s.run_e1[i] - s.run_e0[i]) / s.run_stripes[i]


@njit(inline="always")
def _lacking_count(x1, k0, cx):
    """The columns lacking the channel of a run whose last pixel is x1 and first column holding it k0 (they lie at
    2 k0 + cx + 1 + 2m, up to x1)."""
    return max((x1 - 2 * k0 - cx - 1) // 2 + 1, 0)


@njit(inline="always")
def _carry_sign(n):
    """(-1)^(n - 1): the sign a run of n stripes carries a phase across by (its last stripe's against its first)."""
    return 1 - 2 * ((n - 1) & 1)


@njit(inline="always")
def _phase(vote, voters, width):
    """A run's phase: +1 (the even stripes carry the channel's +1) or -1 by its columns' vote where the model
    takes the run (its stripes' width in range, and all of its columns agreeing but at most `dissent`), else 0.
    (Each column has a sign here, so the sum of the agreements is their count less twice the dissenting ones,
    or minus that.)"""
    dissent = MAX_DISSENT if voters >= MIN_VOTERS else 0
    use = (MIN_WIDTH <= width) & (width <= MAX_WIDTH) & (abs(vote) >= voters - 2 * dissent)
    return use * (1 if vote > 0 else -1)


@njit(inline="always")
def _lacking_bits(odd, phase, signs, count):
    """The bits m < min(count, 8) of whether the channel's sign at a run's m-th column lacking it differs from
    the model's (odd: bit m where the model's stripe there is odd; signs: bit m where c > 0 there, 8 + m where
    c < 0); none for phase 0."""
    plus = (~odd if phase > 0 else odd) & np.int32(255)  # (the model's sign +1)
    agrees = (plus & signs) | (~plus & (signs >> np.int32(8)))
    bits = ~agrees & ((np.int32(1) << np.int32(min(count, 8))) - np.int32(1))
    return bits if phase != 0 else np.int32(0)


@njit(inline="always")
def _odd(x, e0, scale, top):
    """1 where the stripe holding pixel x (as float64) is odd, of the stripes _alternating counts (top: their
    count less one), else 0: its index clamped as a float64, so that the conversion is to int32 (exact: every
    step is, and the clamp to top commutes with the truncation)."""
    return np.int32(min(max((x - e0) * scale, 0.0), top)) & np.int32(1)


@njit(inline="always")
def _bit_count16(v):
    """The set bits of a 16-bit value (int32)."""
    v = v - ((v >> np.int32(1)) & np.int32(0x5555))
    v = (v & np.int32(0x3333)) + ((v >> np.int32(2)) & np.int32(0x3333))
    v = (v + (v >> np.int32(4))) & np.int32(0x0F0F)
    return (v + (v >> np.int32(8))) & np.int32(0x1F)


@njit(inline="always")
def _bit_count8(v):
    """The set bits of an 8-bit value (int32)."""
    v = v - ((v >> np.int32(1)) & np.int32(0x55))
    v = (v & np.int32(0x33)) + ((v >> np.int32(2)) & np.int32(0x33))
    return (v + (v >> np.int32(4))) & np.int32(0x0F)


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
def _alternating(x, e0, scale, n):
    """+1 or -1 by the parity of the stripe of n equal ones from e0 (scale: n over their span) that holds pixel
    x."""
    j = min(int(max((x - e0) * scale, 0.0)), n - 1)
    return 1 - 2 * (j & 1)
