"""Raw Bayer pairs (two-shot): the lacking channel's signs where its columns cannot resolve the stripes.

A Bayer sensor samples B (or R) in every other column, so its Nyquist period is 4 camera pixels; where a
projector stripe is narrower than 2 camera pixels a one-stripe B run is aliased, and the reconstruction's fill
(app/decode/mosaic.py) gives the columns lacking B the wrong sign of B's difference (docs/performance.md,
"Single-chip colour cameras"). G is sampled in every column, and the two-shot code flips one channel at each
stripe edge: inside a run of constant G sign every stripe edge flips B, so between two G edges (located at
full resolution) lie n stripes of equal width with B alternating. Per run: n is one more than the B sign
changes seen at the run's B columns, plus the pairs of changes they missed, from the run's length over the
local stripe width (the median of the neighbouring runs' lengths per seen stripe); the phase is the B
columns' weighted vote, and the run is used only if every B column agrees with it.

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
from core.mosaic import CHANNEL, site_codes

G_STRONG = 0.05  # a G sign counts at |dG| of this share of its local maximum (three 8-pixel blocks)
WINDOW = 6  # runs either side whose widths per stripe give a run's local stripe width (their median)
GROUP = 4  # consecutive runs that share one such median (taken around the group's middle)
MIN_WIDTH = 1.0  # camera pixels per stripe the model accepts for a run
MAX_WIDTH = 3.2


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
        np.zeros(W, np.int8),
        np.empty(W, np.float64),
        np.empty(W, np.float64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.int64),
        np.empty(W, np.float64),
        np.empty(W, np.int64),
    )


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def lacking_row(
    f1: np.ndarray, f2: np.ndarray, y: int, tables: FrameTables, classifier: Classifier, scratch: ClassifyScratch
) -> int:
    """Row y's difference rows (scratch.rows[0:2], as differences wrote them) with the lacking channel's values
    taken as swapped between the frames where the G edges say its sign is wrong; no change without
    classifier.lacking. Returns the pixels changed. The noise floors (rows 2, 3) stay: a sum of both values'."""
    ig, cam, cx = classifier.lacking
    if cam < 0:
        return 0
    rows = scratch.rows
    s = scratch.lacking
    n = lacking_flips(rows[ig], rows[1 - ig], cx, s)
    lin = tables.lin
    u = classifier.unmix
    u00, u01, u02, u10, u11, u12 = u[0, 0], u[0, 1], u[0, 2], u[1, 0], u[1, 1], u[1, 2]
    a = f1[y]
    b = f2[y]
    fv0 = rows[0]
    fv1 = rows[1]
    for i in range(n):
        x = s.flips[i]
        # e_c = lin[c, b] - lin[c, a], a and b exchanged in the lacking channel; then the unmixing in the order
        # of the differences stage (_row_differences, simd.differences16), so that the values are bit-identical
        a0, a1, a2 = a[x, 0], a[x, 1], a[x, 2]
        b0, b1, b2 = b[x, 0], b[x, 1], b[x, 2]
        if cam == 0:
            a0, b0 = b0, a0
        elif cam == 1:
            a1, b1 = b1, a1
        else:
            a2, b2 = b2, a2
        e0 = lin[0, b0] - lin[0, a0]
        e1 = lin[1, b1] - lin[1, a1]
        e2 = lin[2, b2] - lin[2, a2]
        fv0[x] = u00 * e0 + u01 * e1 + u02 * e2
        fv1[x] = u10 * e0 + u11 * e1 + u12 * e2
    return n


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def lacking_flips(g: np.ndarray, c: np.ndarray, cx: int, s: LackingScratch) -> int:
    """The pixels of one row whose lacking channel (differences c, held by the columns of parity cx; G's
    differences g) gets the other sign, into s.flips (each at most once, in increasing order); returns how
    many."""
    W = g.shape[0]
    nb = (W + 7) // 8
    bmax = s.g_max
    sg = s.sign
    edges = s.edges
    no_g, no_c, c_changes, c_sign = s.no_g, s.no_c, s.c_changes, s.c_sign
    r_e0, r_e1, r_x0, r_x1, r_s0, r_s1, r_c, ratio = s.e0, s.e1, s.x0, s.x1, s.s0, s.s1, s.changes, s.ratio
    bmax[0] = 0.0
    bmax[nb + 1] = 0.0
    for k in range(nb):
        m = np.float32(0.0)
        for x in range(8 * k, min(W, 8 * k + 8)):
            m = max(m, abs(g[x]))
        bmax[k + 1] = m
    strong = np.float32(G_STRONG)
    zeros = 0
    for k in range(nb):
        loc = max(bmax[k], max(bmax[k + 1], bmax[k + 2]))
        thr = strong * loc
        lit = loc > 0
        for x in range(8 * k, min(W, 8 * k + 8)):
            v = g[x]
            sign = np.int8(v > 0) - np.int8(v < 0)
            sign = sign if lit & (abs(v) >= thr) else np.int8(0)
            sg[x] = sign
            no_g[x] = zeros
            zeros += sign == 0
    no_g[W] = zeros
    # the channel's columns: their signs (NaN and 0: none), and the counts the runs below read in one step each
    bad = 0
    changes = 0
    prev = np.int8(0)
    for x in range(W):
        no_c[x] = bad
        c_changes[x] = changes
        if (x & 1) == cx:
            v = c[x]
            sign = np.int8(1) if v > 0 else np.int8(-1)
            bad += not (v > 0 or v < 0)
            changes += (prev != 0) & (sign != prev)
            prev = sign
            c_sign[x] = sign
    no_c[W] = bad
    c_changes[W] = changes
    ne = 0
    for x in range(W - 1):
        if sg[x] * sg[x + 1] < 0:
            edges[ne] = x + g[x] / (g[x] - g[x + 1])
            ne += 1
    nr = 0
    for i in range(ne - 1):
        e0 = edges[i]
        e1 = edges[i + 1]
        x0 = int(np.floor(e0)) + 1
        x1 = int(np.floor(e1))
        if x1 < x0:
            continue
        # one G sign throughout: no pixel without one (two opposite neighbours would be an edge between e0, e1)
        ok = no_g[x1 + 1] == no_g[x0]
        # the B columns from one pixel before the first G edge to one after the second (B is constant across a
        # G edge, so those see the run's end stripes)
        s0 = max(int(np.ceil(e0 - 1.0)), 0)
        s1 = min(int(np.floor(e1 + 1.0)), W - 1)
        if (s0 & 1) != cx:
            s0 += 1
        if (s1 & 1) != cx:
            s1 -= 1
        if not ok or s1 < s0 + 2 or no_c[s1 + 1] != no_c[s0]:
            continue
        r_e0[nr] = e0
        r_e1[nr] = e1
        r_x0[nr] = x0
        r_x1[nr] = x1
        r_s0[nr] = s0
        r_s1[nr] = s1
        flips = c_changes[s1 + 1] - c_changes[s0 + 1]  # (the changes from s0 to s1)
        r_c[nr] = flips
        ratio[nr] = (e1 - e0) / (flips + 1)
        nr += 1
    w = 0.0
    n_flip = 0
    for i in range(nr):
        if i % GROUP == 0:
            centre = min(i + GROUP // 2, nr - 1)
            w = _median(ratio, max(0, centre - WINDOW), min(nr, centre + WINDOW + 1))
        e0 = r_e0[i]
        span = r_e1[i] - e0
        seen = r_c[i] + 1
        n = seen + 2 * max(0, int(np.round((span / w - seen) / 2.0)))
        if not (MIN_WIDTH <= span / n <= MAX_WIDTH):
            continue
        scale = n / span
        # the phase: the B columns' sign against the model's alternation, used where all of them agree (they all
        # have a sign here, so that is where their weighted vote has that sign and each agrees with it)
        phase = 0
        for q in range(r_s0[i], r_s1[i] + 1, 2):
            t = _alternating(q, e0, scale, n) * c_sign[q]
            phase = t if phase == 0 else (phase if t == phase else 2)
        if phase == 2:
            continue
        for x in range(r_x0[i], r_x1[i] + 1):
            if (x & 1) != cx and not (phase * _alternating(x, e0, scale, n) * c[x] > 0):
                s.flips[n_flip] = x
                n_flip += 1
    return n_flip


@njit(inline="always")
def _median(v, lo, hi):
    """The median of v[lo:hi] (the mean of the middle two for an even count), by counting for each value those
    below and equal to it: branch-free loops, where a sort's branches are mispredicted."""
    m = hi - lo
    k = m // 2
    upper = 0.0
    lower = 0.0
    for q in range(m):
        t = v[lo + q]
        less = 0
        same = 0
        for p in range(m):
            u = v[lo + p]
            less += u < t
            same += u == t
        upper = t if (less <= k) & (k < less + same) else upper
        lower = t if (less <= k - 1) & (k - 1 < less + same) else lower
    return upper if m & 1 else 0.5 * (lower + upper)


@njit(inline="always")
def _alternating(x, e0, scale, n):
    """+1 or -1 by the parity of the stripe of n equal ones from e0 (scale: n over their span) that holds pixel
    x."""
    j = min(int(max((x - e0) * scale, 0.0)), n - 1)
    return 1 - 2 * (j & 1)
