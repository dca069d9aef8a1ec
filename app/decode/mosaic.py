"""Raw Bayer frames to RGB for the stripe decoders: a reconstruction that follows the stripes.

The projected stripes are vertical, so along a camera column the pattern does not change. Every column of a
Bayer sensor holds G and one of R or B at alternate rows: those two are taken from the pixel itself or the
mean of the pixels above and below (the same stripe), never from the neighbouring columns, which see other
stripes. The third channel (B in an R column, R in a B column) exists only in the columns either side; it is
interpolated across the row with the four-tap cubic (-1, 9, 9, -1) / 16 over columns x-3, x-1, x+1, x+3 (of
the same channel), linear at the image edges. A photographic demosaic instead averages G across the row at R
and B sites, blurring the G stripes by a neighbour's half (docs/performance.md, "Single-chip colour cameras").

The two-shot code's G channel is thereby as sharp as a 3-CCD camera's; B has half the columns, its zero
crossings interpolated between them. The decoder's crosstalk unmixing then acts on the reconstructed RGB.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from core.errors import InputError
from core.mosaic import mosaic_name, site_codes


def stripe_rgb(raw: np.ndarray, mosaic: str, out: np.ndarray | None = None) -> np.ndarray:
    """The RGB frame (H, W, 3) of a raw Bayer frame (H, W) uint8 or uint16, in the raw frame's dtype."""
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
    top = np.int32(np.iinfo(raw.dtype).max)
    _stripe_rgb(np.ascontiguousarray(raw), site_codes(name), top, out.reshape(H, W * 3))
    return out


def to_rgb(image: np.ndarray, mosaic: str | None) -> np.ndarray:
    """image as RGB: a raw Bayer frame (2-D) through stripe_rgb with its mosaic, an RGB frame as it is."""
    if image.ndim == 2:
        return stripe_rgb(image, mosaic)
    return image


@njit(cache=True, nogil=True, error_model="numpy")
def _stripe_rgb(raw, codes, top, out):
    """out: (H, 3 W), the RGB frame's rows."""
    H, W = raw.shape
    own = np.empty(W, np.int32)  # this row's samples
    vert = np.empty(W, np.int32)  # the mean of the rows above and below (the same stripe)
    # the column parities holding R and B (G is in every column, at this row's own sites of parity gx)
    rx = 0 if (codes[0, 0] == 0 or codes[1, 0] == 0) else 1
    bx = 1 - rx
    for y in range(H):
        a = raw[y]
        u = raw[y - 1 if y > 0 else y + 1]
        d = raw[y + 1 if y + 1 < H else y - 1]
        for x in range(W):
            own[x] = a[x]
            vert[x] = (np.int32(u[x]) + np.int32(d[x]) + 1) >> 1
        py = y & 1
        gx = 0 if codes[py, 0] == 1 else 1
        # R and B in the columns holding them: this row's sample there, or the rows above and below
        rs = own if codes[py, rx] == 0 else vert
        bs = own if codes[py, bx] == 2 else vert
        row = out[y]
        for x in range(min(3, W)):
            _edge_pixel(rs, bs, own, vert, x, W, rx, gx, row)
        # the interior, branch-free (the compiler vectorises it): the column's own channels, and the cubic
        # (-1, 9, 9, -1) / 16 across the row for the one it lacks
        for x in range(3, W - 3):
            odd = x & 1
            row[3 * x] = rs[x] if odd == rx else _across(rs, x, top)
            row[3 * x + 1] = own[x] if odd == gx else vert[x]
            row[3 * x + 2] = bs[x] if odd == bx else _across(bs, x, top)
        for x in range(max(3, W - 3), W):
            _edge_pixel(rs, bs, own, vert, x, W, rx, gx, row)


@njit(inline="always")
def _across(src, x, top):
    return min(max((9 * (src[x - 1] + src[x + 1]) - src[x - 3] - src[x + 3] + 8) >> 4, 0), top)


@njit(inline="always")
def _edge_pixel(rs, bs, own, vert, x, W, rx, gx, row):
    """A pixel near the image's edge (the cubic's taps reach 3 columns): the lacking channel linear across, or
    its one neighbour."""
    row[3 * x] = _edge_value(rs, x, W, rx)
    row[3 * x + 1] = own[x] if (x & 1) == gx else vert[x]
    row[3 * x + 2] = _edge_value(bs, x, W, 1 - rx)


@njit(inline="always")
def _edge_value(src, x, W, cx):
    if (x & 1) == cx:
        return src[x]
    if x >= 1 and x + 1 < W:
        return (src[x - 1] + src[x + 1] + 1) >> 1
    return src[x + 1 if x == 0 else x - 1]
