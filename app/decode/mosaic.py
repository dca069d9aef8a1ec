"""Raw Bayer frames to RGB for the stripe decoders: a reconstruction that follows the stripes.

The projected stripes are vertical, so along a camera column the pattern does not change. Every column of a
Bayer sensor holds G and one of R or B at alternate rows: those two are taken from the pixel itself or the
mean of the pixels above and below (the same stripe), never from the neighbouring columns, which see other
stripes. The third channel (B in an R column, R in a B column) exists only in the columns either side; it is
interpolated across the row with the four-tap cubic (-1, 9, 9, -1) / 16 over columns x-3, x-1, x+1, x+3 (of
the same channel), linear at the image edges. A photographic demosaic instead averages G across the row at R
and B sites, blurring the G stripes by a neighbour's half (docs/performance.md, "Single-chip colour cameras").

The lacking channel c is filled consistently with the decoder's crosstalk unmixing: camera channel c holds
k times the G it sees (k = -U[c, G] / U[c, c] of the unmixing matrix U, mosaic_leaks), and G differs from
column to column (its stripes), so what is interpolated across the row is c - k G, to which column x's own
(exact) G is added back as k G[x]. The unmixed c then does not depend on G at x at all, where an interpolated
c would carry the neighbours' G leaks, of the wrong stripes.

The two-shot code's G channel is thereby as sharp as a 3-CCD camera's; B has half the columns, its zero
crossings interpolated between them. The decoder's crosstalk unmixing then acts on the reconstructed RGB.
"""

from __future__ import annotations

import cv2
import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.colour import unmixing_matrix
from core.errors import InputError
from core.mosaic import mosaic_name, site_codes

# the leaks in fixed point of LEAK_BITS fractional bits; |k| <= MAX_LEAK keeps the fill's sums of 16-bit samples
# inside int32 (cubic 20 * 65535 * 2**8, plus 2**8 times G's high-pass, at most 36 * 65535: < 2**30)
LEAK_BITS = 8
MAX_LEAK = 1.0
NO_LEAKS = (0.0, 0.0)


def mosaic_leaks(color_mixing: np.ndarray | None) -> tuple[float, float]:
    """(k_R, k_B): the share of camera G that camera R and camera B carry as the decoder's unmixing sees it,
    k_c = -U[c, G] / U[c, c] of the unmixing matrix U (app/decode/colour.py); (0, 0) without colour mixing."""
    U = unmixing_matrix(color_mixing).astype(np.float64)
    leaks = []
    for c in (0, 2):
        k = -U[c, 1] / U[c, c] if U[c, c] != 0 else 0.0
        leaks.append(float(np.clip(k, -MAX_LEAK, MAX_LEAK)) if np.isfinite(k) else 0.0)
    return leaks[0], leaks[1]


def stripe_rgb(
    raw: np.ndarray, mosaic: str, out: np.ndarray | None = None, leaks: tuple[float, float] = NO_LEAKS
) -> np.ndarray:
    """The RGB frame (H, W, 3) of a raw Bayer frame (H, W) uint8 or uint16, in the raw frame's dtype. leaks:
    (k_R, k_B) of mosaic_leaks, the G the lacking channel is filled consistently with (none by default)."""
    name = mosaic_name(mosaic, "mosaic")
    if name is None:
        raise InputError("a raw Bayer frame needs its mosaic (RGGB, GRBG, GBRG or BGGR)")
    if raw.ndim != 2 or raw.dtype not in (np.uint8, np.uint16):
        raise InputError(f"a raw Bayer frame must be (H, W) uint8 or uint16, found {raw.dtype} {raw.shape}")
    H, W = raw.shape
    if H < 2 or W < 2:
        raise InputError(f"a raw Bayer frame must be at least 2x2 pixels, found {W}x{H}")
    if out is None:
        out = np.empty((H, W, 3), raw.dtype)
    if not (out.shape == (H, W, 3) and out.dtype == raw.dtype and out.flags.c_contiguous):
        raise ValueError(f"out must be a C-contiguous {raw.dtype} (H, W, 3) array, found {out.dtype} {out.shape}")
    kr, kb = (round(float(np.clip(k, -MAX_LEAK, MAX_LEAK)) * (1 << LEAK_BITS)) for k in leaks)
    # one plane per channel (contiguous stores, which the compiler vectorises), interleaved by OpenCV's merge
    planes = np.empty((3, H, W), raw.dtype)
    top = np.int32(np.iinfo(raw.dtype).max)
    _stripe_planes(np.ascontiguousarray(raw), site_codes(name), top, np.int32(kr), np.int32(kb), *planes)
    cv2.merge([planes[0], planes[1], planes[2]], dst=out)
    return out


def to_rgb(image: np.ndarray, mosaic: str | None, leaks: tuple[float, float] = NO_LEAKS) -> np.ndarray:
    """image as RGB: a raw Bayer frame (2-D) through stripe_rgb with its mosaic (and leaks), an RGB frame as it
    is."""
    if image.ndim == 2:
        return stripe_rgb(image, mosaic, leaks=leaks)
    return image


@njit(cache=True, nogil=True, error_model="numpy")
def _stripe_planes(raw, codes, top, kr, kb, red, green, blue):
    """red, green, blue: (H, W) planes, written. kr, kb: the leaks in fixed point (LEAK_BITS)."""
    H, W = raw.shape
    # float32 throughout the row loop: eight lanes a register (numba widens int32 arithmetic to int64), and exact
    # on these integers (sums below 2**24: the cubic's 20 * 65535); the fill rounds as (sum + 8) >> 4 would
    f9 = np.float32(9.0)
    f16 = np.float32(16.0)
    sixteenth = np.float32(1.0 / 16.0)
    f_half = np.float32(0.5)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    f_top = np.float32(top)
    own = np.empty(W, np.float32)  # this row's samples
    vert = np.empty(W, np.float32)  # the mean of the rows above and below (the same stripe), rounded
    # the column parities holding R and B (G is in every column, at this row's own sites of parity gx)
    rx = 0 if (codes[0, 0] == 0 or codes[1, 0] == 0) else 1
    # per column: 1 where it holds R (0: B), and the leak of the channel it lacks
    at_r = np.empty(W, np.float32)
    leak = np.empty(W, np.float32)
    fr = np.float32(kr / (1 << LEAK_BITS))
    fb = np.float32(kb / (1 << LEAK_BITS))
    for x in range(W):
        at_r[x] = one if (x & 1) == rx else zero
        leak[x] = fb if (x & 1) == rx else fr
    own_g = (np.zeros(W, np.float32), np.zeros(W, np.float32))  # per gx: 1 where own holds G
    for x in range(W):
        own_g[x & 1][x] = one
    for y in range(H):
        a = raw[y]
        u = raw[y - 1 if y > 0 else y + 1]
        d = raw[y + 1 if y + 1 < H else y - 1]
        for x in range(W):
            own[x] = np.float32(a[x])
            vert[x] = np.floor((np.float32(u[x]) + np.float32(d[x]) + one) * f_half)
        mg = own_g[0 if codes[y & 1, 0] == 1 else 1]
        r = red[y]
        g = green[y]
        b = blue[y]
        # the interior, branch-free (the compiler vectorises it): blends by the 0/1 masks, exact. Column x's
        # neighbours at odd distances hold the other parity, so of the cubics (-1, 9, 9, -1) / 16 across the row of
        # this row's samples (co) and of the vertical means (cv), one is G's and the other that of the channel x
        # lacks: where own[x] is G, co is the lacking channel's; elsewhere cv. The fill is the lacking channel's
        # cubic plus k (G[x] - G's cubic), k that channel's leak.
        for x in range(3, W - 3):
            o = own[x]
            v = vert[x]
            co = f9 * (own[x - 1] + own[x + 1]) - own[x - 3] - own[x + 3]
            cv = f9 * (vert[x - 1] + vert[x + 1]) - vert[x - 3] - vert[x + 3]
            m = mg[x]
            gv = v + m * (o - v)
            held = o + v - gv
            c_lack = cv + m * (co - cv)
            c_g = co + cv - c_lack
            fill = np.floor((c_lack + leak[x] * (f16 * gv - c_g)) * sixteenth + f_half)
            fill = zero if fill < zero else fill
            fill = f_top if fill > f_top else fill
            mr = at_r[x]
            r[x] = np.int32(fill + mr * (held - fill))
            g[x] = np.int32(gv)
            b[x] = np.int32(held + mr * (fill - held))
        _edge_row(raw, codes, y, rx, kr, kb, top, r, g, b)  # (a call of its own: the loop above stays vectorised)


@njit(nogil=True, error_model="numpy")
def _edge_row(raw, codes, y, rx, kr, kb, top, r, g, b):
    """Row y's pixels within 3 columns of the image's edges, where the cubic's taps would leave it, into the
    plane rows r, g, b: the lacking channel's c - k G linear across, or from its one neighbour, plus k G of the
    column."""
    H, W = raw.shape
    y0 = y - 1 if y > 0 else y + 1
    y1 = y + 1 if y + 1 < H else y - 1
    for i in range(6):
        x = i if i < 3 else W - 6 + i
        if x < 0 or x >= W:
            continue
        gv = _held(raw, codes, y, y0, y1, x, 1)
        g[x] = gv
        r[x] = _edge_value(raw, codes, y, y0, y1, x, 0, rx, kr, gv, top)
        b[x] = _edge_value(raw, codes, y, y0, y1, x, 2, 1 - rx, kb, gv, top)


@njit(inline="always")
def _edge_value(raw, codes, y, y0, y1, x, c, cx, k, gv, top):
    """Channel c at an edge pixel (y, x) (_edges) whose G is gv; cx: the column parity holding c."""
    if (x & 1) == cx:
        return _held(raw, codes, y, y0, y1, x, c)
    S = LEAK_BITS
    W = raw.shape[1]
    if x >= 1 and x + 1 < W:
        t = _lean(raw, codes, y, y0, y1, x - 1, c, k) + _lean(raw, codes, y, y0, y1, x + 1, c, k)
        t = (t + k * gv * 2 + (1 << S)) >> (S + 1)
    else:
        t = _lean(raw, codes, y, y0, y1, x + 1 if x == 0 else x - 1, c, k)
        t = (t + k * gv + (1 << (S - 1))) >> S
    return min(max(t, 0), top)


@njit(inline="always")
def _held(raw, codes, y, y0, y1, x, c):
    """Channel c in column x (which holds it) on row y: the site's sample, or the mean of the rows above and
    below."""
    if codes[y & 1, x & 1] == c:
        return np.int32(raw[y, x])
    return (np.int32(raw[y0, x]) + np.int32(raw[y1, x]) + 1) >> 1


@njit(inline="always")
def _lean(raw, codes, y, y0, y1, x, c, k):
    """(c - k G) * 2**LEAK_BITS in column x (which holds c) on row y."""
    return (_held(raw, codes, y, y0, y1, x, c) << LEAK_BITS) - k * _held(raw, codes, y, y0, y1, x, 1)
