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
c would carry the neighbours' G leaks, of the wrong stripes. Light adds linearly and the unmixing acts on
linear values, so the fill is computed in linear light through the camera response the decoder linearises
with (a gamma-encoding camera's codes are not linear), and stored as the nearest code (response_inverse.py).

The two-shot code's G channel is thereby as sharp as a 3-CCD camera's; B has half the columns, its zero
crossings interpolated between them. The decoder's crosstalk unmixing then acts on the reconstructed RGB.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.colour import unmixing_matrix
from app.decode.primitives import gather
from app.decode.response_inverse import ResponseInverse, identity_inverse, nearest_code
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
    raw: np.ndarray,
    mosaic: str,
    out: np.ndarray | None = None,
    leaks: tuple[float, float] = NO_LEAKS,
    response: ResponseInverse | None = None,
) -> np.ndarray:
    """The RGB frame (H, W, 3) of a raw Bayer frame (H, W) uint8 or uint16, in the raw frame's dtype. leaks:
    (k_R, k_B) of mosaic_leaks, the G the lacking channel is filled consistently with (none by default);
    response: the camera response the fill is computed through (response_inverse of the decoder's table for
    this depth; by default the codes are taken as linear)."""
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
    inverse = response if response is not None else identity_inverse(raw.dtype)
    levels = 65536 if raw.dtype == np.uint16 else 256
    if inverse.lin.shape != (3, levels):
        raise ValueError(f"the camera response has {inverse.lin.shape[1]} codes, the frame {levels}")
    # one plane per channel (contiguous stores, which the compiler vectorises), interleaved by OpenCV's merge
    planes = np.empty((3, H, W), raw.dtype)
    _stripe_planes(np.ascontiguousarray(raw), site_codes(name), (np.int32(kr), np.int32(kb)), inverse, planes)
    cv2.merge([planes[0], planes[1], planes[2]], dst=out)
    return out


def to_rgb(
    image: np.ndarray,
    mosaic: str | None,
    leaks: tuple[float, float] = NO_LEAKS,
    response: ResponseInverse | None = None,
) -> np.ndarray:
    """image as RGB: a raw Bayer frame (2-D) through stripe_rgb with its mosaic (and leaks, response), an RGB
    frame as it is."""
    if image.ndim == 2:
        return stripe_rgb(image, mosaic, leaks=leaks, response=response)
    return image


@njit(cache=True, nogil=True, error_model="numpy")
def _stripe_planes(raw, codes, leaks, response, planes):
    """planes (3, H, W): R, G, B, written. leaks: (k_R, k_B) in fixed point (LEAK_BITS); response: the camera
    response and its inverse (ResponseInverse)."""
    H, W = raw.shape
    red, green, blue = planes[0], planes[1], planes[2]
    kr, kb = leaks
    lin = response.lin
    levels = lin.shape[1]
    top = levels - 1
    inverse = response.codes
    scale = response.scale
    root = response.root
    steps = inverse.shape[0] // 3  # (the entries of each channel's inverse)
    flat_lin = lin.ravel()
    above = inverse[1:]  # (each entry's next: the interpolation's upper end, by the same index)
    fills = FillTables(flat_lin, levels, inverse, scale, root, np.float32(steps - 2))
    # float32 throughout the row loops: eight lanes a register (numba widens int32 arithmetic to int64); the table
    # reads are vector gathers of their own (primitives.gather)
    f9 = np.float32(9.0)
    f16 = np.float32(16.0)
    sixteenth = np.float32(1.0 / 16.0)
    f_half = np.float32(0.5)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    last = np.float32(steps - 2)
    f_top = np.float32(top)
    own = np.empty(W, np.float32)  # this row's samples
    vert = np.empty(W, np.float32)  # the mean of the rows above and below (the same stripe), rounded
    lin_rows = np.empty((3, W), np.float32)  # raw rows y - 1, y, y + 1 in linear light (each by its row mod 3)
    vert_lin = np.empty(W, np.float32)  # the mean of the rows above and below in linear light
    at = np.empty(W, np.int32)  # table indices: of the samples, then of the fills' inverse steps
    frac = np.empty(W, np.float32)  # the fills' position between two inverse steps
    below_code = np.empty(W, np.float32)  # the inverse at those two steps
    above_code = np.empty(W, np.float32)
    # the column parities holding R and B (G is in every column, at this row's own sites of parity gx)
    rx = 0 if (codes[0, 0] == 0 or codes[1, 0] == 0) else 1
    # per column: 1 where it holds R (0: B), the leak of the channel it lacks and where that channel's inverse starts
    at_r = np.empty(W, np.float32)
    leak = np.empty(W, np.float32)
    lacking_at = np.empty(W, np.int32)
    fr = np.float32(kr / (1 << LEAK_BITS))
    fb = np.float32(kb / (1 << LEAK_BITS))
    for x in range(W):
        at_r[x] = one if (x & 1) == rx else zero
        leak[x] = fb if (x & 1) == rx else fr
        lacking_at[x] = 2 * steps if (x & 1) == rx else 0
    own_g = (np.zeros(W, np.float32), np.zeros(W, np.float32))  # per gx: 1 where own holds G
    for x in range(W):
        own_g[x & 1][x] = one
    for yy in range(min(2, H)):
        _linear_row(raw, yy, codes, fills, at, lin_rows[yy % 3])
    for y in range(H):
        if 1 <= y < H - 1:
            _linear_row(raw, y + 1, codes, fills, at, lin_rows[(y + 1) % 3])
        yu = y - 1 if y > 0 else y + 1
        yd = y + 1 if y + 1 < H else y - 1
        a = raw[y]
        u = raw[yu]
        d = raw[yd]
        for x in range(W):
            own[x] = np.float32(a[x])
            vert[x] = np.floor((np.float32(u[x]) + np.float32(d[x]) + one) * f_half)
        own_lin = lin_rows[y % 3]
        lu = lin_rows[yu % 3]
        ld = lin_rows[yd % 3]
        for x in range(W):
            vert_lin[x] = f_half * (lu[x] + ld[x])
        mg = own_g[0 if codes[y & 1, 0] == 1 else 1]
        r = red[y]
        g = green[y]
        b = blue[y]
        # the interior, branch-free (the compiler vectorises it): blends by the 0/1 masks, exact. Column x's
        # neighbours at odd distances hold the other parity, so of the cubics (-1, 9, 9, -1) / 16 across the row of
        # this row's samples (co) and of the vertical means (cv), one is G's and the other that of the channel x
        # lacks: where own[x] is G, co is the lacking channel's; elsewhere cv. The fill is the lacking channel's
        # cubic plus k (G[x] - G's cubic), k that channel's leak, in linear light; then its inverse step.
        for x in range(3, W - 3):
            ol = own_lin[x]
            vl = vert_lin[x]
            m = mg[x]
            co = f9 * (own_lin[x - 1] + own_lin[x + 1]) - own_lin[x - 3] - own_lin[x + 3]
            cv = f9 * (vert_lin[x - 1] + vert_lin[x + 1]) - vert_lin[x - 3] - vert_lin[x + 3]
            gl = vl + m * (ol - vl)
            c_lack = cv + m * (co - cv)
            c_g = co + cv - c_lack
            fill = (c_lack + leak[x] * (f16 * gl - c_g)) * sixteenth
            v = max(fill, zero)
            t = min((np.sqrt(v) if root else v) * scale, last)
            j = np.int32(t)
            frac[x] = t - np.float32(j)
            at[x] = lacking_at[x] + j
        gather(below_code[3:], inverse, at[3:], W - 6)
        gather(above_code[3:], above, at[3:], W - 6)
        # the codes: the held channels' exact, the fill's from its inverse, interpolated and rounded half up
        for x in range(3, W - 3):
            o = own[x]
            v = vert[x]
            m = mg[x]
            gv = v + m * (o - v)
            held = o + v - gv
            lo = below_code[x]
            code = np.floor(lo + frac[x] * (above_code[x] - lo) + f_half)
            code = min(max(code, zero), f_top)
            mr = at_r[x]
            g[x] = np.int32(gv)
            r[x] = np.int32(code + mr * (held - code))
            b[x] = np.int32(held + mr * (code - held))
        _edge_row(raw, y, codes, rx, leaks, fills, r, g, b)  # (a call of its own: the loops above stay simple)


class FillTables(NamedTuple):
    """The camera response for the edge columns' fill: lin (3 levels,) float32 flat, levels, the inverse (codes),
    scale and root (ResponseInverse), the highest step an interpolation starts from (last, float32)."""

    lin: np.ndarray
    levels: int
    inverse: np.ndarray
    scale: np.float32
    root: bool
    last: np.float32


@njit(nogil=True, error_model="numpy", _nrt=False)
def _linear_row(raw, y, codes, fills, at, out):
    """out: raw row y in linear light, each sample through its own channel's response (at: index scratch)."""
    W = raw.shape[1]
    c0 = codes[y & 1, 0] * fills.levels
    c1 = codes[y & 1, 1] * fills.levels
    a = raw[y]
    for x in range(W):
        at[x] = (c1 if x & 1 else c0) + np.int32(a[x])
    gather(out, fills.lin, at, W)


@njit(nogil=True, error_model="numpy", _nrt=False)
def _edge_row(raw, y, codes, rx, leaks, fills, r, g, b):
    """Row y's pixels within 3 columns of the image's edges, where the cubic's taps would leave it, into the
    plane rows r, g, b: the lacking channel's c - k G linear across, or from its one neighbour, plus k G of the
    column, in linear light."""
    H, W = raw.shape
    y0 = y - 1 if y > 0 else y + 1
    y1 = y + 1 if y + 1 < H else y - 1
    rows = (y, y0, y1)
    for i in range(6):
        x = i if i < 3 else W - 6 + i
        if x < 0 or x >= W:
            continue
        gv = _held(raw, codes, rows, x, 1)
        g[x] = gv
        r[x] = _edge_value(raw, codes, rows, x, 0, rx, leaks[0], gv, fills)
        b[x] = _edge_value(raw, codes, rows, x, 2, 1 - rx, leaks[1], gv, fills)


@njit(inline="always")
def _edge_value(raw, codes, rows, x, c, cx, k, gv, fills):
    """Channel c at an edge pixel (rows[0], x) whose G is gv; cx: the column parity holding c; k: c's leak."""
    if (x & 1) == cx:
        return _held(raw, codes, rows, x, c)
    W = raw.shape[1]
    kf = k / (1 << LEAK_BITS)
    if x >= 1 and x + 1 < W:
        t = 0.5 * (_lean(raw, codes, rows, x - 1, c, kf, fills) + _lean(raw, codes, rows, x + 1, c, kf, fills))
    else:
        t = _lean(raw, codes, rows, x + 1 if x == 0 else x - 1, c, kf, fills)
    value = t + kf * fills.lin[fills.levels + gv]
    at = c * (fills.inverse.shape[0] // 3)
    return np.int32(nearest_code(value, at, fills.inverse, fills.scale, fills.root, fills.last, fills.levels - 1))


@njit(inline="always")
def _held(raw, codes, rows, x, c):
    """Channel c in column x (which holds it) on row rows[0]: the site's sample, or the mean of the rows above and
    below (rows[1], rows[2])."""
    y, y0, y1 = rows
    if codes[y & 1, x & 1] == c:
        return np.int32(raw[y, x])
    return (np.int32(raw[y0, x]) + np.int32(raw[y1, x]) + 1) >> 1


@njit(inline="always")
def _lean(raw, codes, rows, x, c, k, fills):
    """c - k G in linear light in column x (which holds c) on row rows[0]."""
    lin, levels = fills.lin, fills.levels
    return lin[c * levels + _held(raw, codes, rows, x, c)] - k * lin[levels + _held(raw, codes, rows, x, 1)]
