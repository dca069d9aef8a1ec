"""Raw Bayer pairs (two-shot): the lacking channel's signs where its columns cannot resolve the stripes.

A Bayer sensor samples B (or R) in every other column, so its Nyquist period is 4 camera pixels; where a
projector stripe is narrower than 2 camera pixels a one-stripe B run is aliased, and the reconstruction's fill
(app/decode/mosaic.py) gives the columns lacking B the wrong sign of B's difference (docs/performance.md,
"Single-chip colour cameras"). G is sampled in every column, and the two-shot code flips one channel at each
stripe edge: inside a run of constant G sign every stripe edge flips B, so between two G edges (located at
full resolution) lie n stripes of equal width with B alternating. Per run: n is one more than the B sign
changes seen at the run's B columns, plus the pairs of changes they missed, from the run's length over the
local stripe width (the median of the neighbouring runs' lengths per seen stripe); the phase is the B
columns' weighted vote, and the run is used only if every B column agrees with it. Where the fill's sign at
a column lacking B disagrees, the two frames' B values there are swapped (the sign flips, the magnitude and the
pair's mean stay).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.differences import differences
from core.mosaic import CHANNEL, site_codes

G_STRONG = 0.05  # a G sign counts at |dG| of this share of its local maximum (three 8-pixel blocks)
WINDOW = 6  # runs either side whose widths per stripe give a run's local stripe width (their median)
GROUP = 4  # consecutive runs that share one such median (taken around the group's middle)
MIN_WIDTH = 1.0  # camera pixels per stripe the model accepts for a run
MAX_WIDTH = 3.2


def lacking_signs(rgb1: np.ndarray, rgb2: np.ndarray, mosaic: str, decoder: object) -> tuple[np.ndarray, np.ndarray]:
    """The pair (rgb1, rgb2) (frames reconstructed from raw mosaics, in pattern order) with the lacking channel's
    values swapped between the frames where the G edges say its sign is wrong (new arrays; the inputs as they
    are for patterns other than G and one other channel). decoder: the pair's TwoShotDecoder (its tables and
    unmixing: the same differences the decoder takes)."""
    channels = str(decoder.channels).upper()
    if len(channels) != 2 or "G" not in channels or rgb1.ndim != 3:
        return rgb1, rgb2
    ig = channels.index("G")
    cam = CHANNEL[channels[1 - ig]]
    codes = site_codes(mosaic)
    cx = 0 if (codes[0, 0] == cam or codes[1, 0] == cam) else 1  # the column parity holding the channel
    lin, dlin, packed = decoder.tables(rgb1.dtype)
    f1 = np.ascontiguousarray(rgb1)
    f2 = np.ascontiguousarray(rgb2)
    o1 = f1.copy()
    o2 = f2.copy()
    _fix_pair(f1, f2, lin, dlin, packed, decoder.unmix, ig, cam, cx, o1, o2)
    return o1, o2


@njit(cache=True, nogil=True, error_model="numpy")
def _fix_pair(f1, f2, lin, dlin, packed, unmix, ig, cam, cx, o1, o2):
    """o1, o2: copies of f1, f2, changed where the lacking channel (camera channel cam, held by the columns of
    parity cx) gets the other sign; returns how many pixels changed."""
    H, W = f1.shape[0], f1.shape[1]
    rows = np.empty((4, W), np.float32)
    ahead = ((np.zeros((1, 1), np.float32), 0),)
    nb = (W + 7) // 8
    bmax = np.zeros(nb + 2, np.float32)
    sg = np.zeros(W, np.int8)
    edges = np.empty(W, np.float64)
    # the row's usable G runs: edges, pixels, first and last B column, B sign changes seen, length per stripe
    r_e0 = np.empty(W, np.float64)
    r_e1 = np.empty(W, np.float64)
    r_x0 = np.empty(W, np.int64)
    r_x1 = np.empty(W, np.int64)
    r_s0 = np.empty(W, np.int64)
    r_s1 = np.empty(W, np.int64)
    r_c = np.empty(W, np.int64)
    ratio = np.empty(W, np.float64)
    changed = 0
    for y in range(H):
        differences(f1, f2, y, lin, dlin, packed, unmix, np.float32(0.0), rows, ahead)
        g = rows[ig]
        c = rows[1 - ig]
        for k in range(nb):
            m = np.float32(0.0)
            for x in range(8 * k, min(W, 8 * k + 8)):
                m = max(m, abs(g[x]))
            bmax[k + 1] = m
        strong = np.float32(G_STRONG)
        for x in range(W):
            k = x // 8 + 1
            loc = max(bmax[k - 1], max(bmax[k], bmax[k + 1]))
            v = g[x]
            sign = np.int8(v > 0) - np.int8(v < 0)
            sg[x] = sign if (loc > 0) & (abs(v) >= strong * loc) else np.int8(0)
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
            ok = True
            for x in range(x0, x1 + 1):
                ok &= sg[x] == sg[x0]
            # the B columns from one pixel before the first G edge to one after the second (B is constant across
            # a G edge, so those see the run's end stripes)
            s0 = max(int(np.ceil(e0 - 1.0)), 0)
            s1 = min(int(np.floor(e1 + 1.0)), W - 1)
            if (s0 & 1) != cx:
                s0 += 1
            if (s1 & 1) != cx:
                s1 -= 1
            if not ok or s1 < s0 + 2:
                continue
            flips = 0
            prev = 0
            for s in range(s0, s1 + 1, 2):
                sv = c[s]
                if not (sv > 0 or sv < 0):
                    ok = False
                sgn = 1 if sv > 0 else -1
                if prev != 0 and sgn != prev:
                    flips += 1
                prev = sgn
            if not ok:
                continue
            r_e0[nr] = e0
            r_e1[nr] = e1
            r_x0[nr] = x0
            r_x1[nr] = x1
            r_s0[nr] = s0
            r_s1[nr] = s1
            r_c[nr] = flips
            ratio[nr] = (e1 - e0) / (flips + 1)
            nr += 1
        w = 0.0
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
            vote = 0.0
            for s in range(r_s0[i], r_s1[i] + 1, 2):
                vote += _alternating(s, e0, scale, n) * c[s]
            if vote == 0:
                continue
            phase = 1 if vote > 0 else -1
            ok = True
            for s in range(r_s0[i], r_s1[i] + 1, 2):
                ok &= phase * _alternating(s, e0, scale, n) * c[s] > 0
            if not ok:
                continue
            for x in range(r_x0[i], r_x1[i] + 1):
                if (x & 1) != cx and not (phase * _alternating(x, e0, scale, n) * c[x] > 0):
                    o1[y, x, cam] = f2[y, x, cam]
                    o2[y, x, cam] = f1[y, x, cam]
                    changed += 1
    return changed


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
