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

import cv2
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
    # one plane per channel (contiguous stores, which the compiler vectorises), interleaved by OpenCV's merge
    planes = np.empty((3, H, W), raw.dtype)
    _stripe_planes(np.ascontiguousarray(raw), site_codes(name), np.int32(np.iinfo(raw.dtype).max), *planes)
    cv2.merge([planes[0], planes[1], planes[2]], dst=out)
    return out


def to_rgb(image: np.ndarray, mosaic: str | None) -> np.ndarray:
    """image as RGB: a raw Bayer frame (2-D) through stripe_rgb with its mosaic, an RGB frame as it is."""
    if image.ndim == 2:
        return stripe_rgb(image, mosaic)
    return image


@njit(cache=True, nogil=True, error_model="numpy")
def _stripe_planes(raw, codes, top, red, green, blue):
    """red, green, blue: (H, W) planes, written."""
    H, W = raw.shape
    own = np.empty(W, np.int32)  # this row's samples
    vert = np.empty(W, np.int32)  # the mean of the rows above and below (the same stripe)
    # the column parities holding R and B (G is in every column, at this row's own sites of parity gx)
    rx = 0 if (codes[0, 0] == 0 or codes[1, 0] == 0) else 1
    bx = 1 - rx
    _edges(raw, codes, rx, red, green, blue)  # (apart: in the row loop they kept the interior scalar)
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
        r = red[y]
        g = green[y]
        b = blue[y]
        # the interior, branch-free (the compiler vectorises it): the column's own channels, and the cubic
        # (-1, 9, 9, -1) / 16 across the row for the one it lacks
        for x in range(3, W - 3):
            odd = x & 1
            ra = min(max((9 * (rs[x - 1] + rs[x + 1]) - rs[x - 3] - rs[x + 3] + 8) >> 4, 0), top)
            ba = min(max((9 * (bs[x - 1] + bs[x + 1]) - bs[x - 3] - bs[x + 3] + 8) >> 4, 0), top)
            r[x] = rs[x] if odd == rx else ra
            g[x] = own[x] if odd == gx else vert[x]
            b[x] = bs[x] if odd == bx else ba


@njit(nogil=True, error_model="numpy")
def _edges(raw, codes, rx, red, green, blue):
    """The pixels within 3 columns of the image's edges, where the cubic's taps would leave it: the lacking
    channel linear across, or from its one neighbour."""
    H, W = raw.shape
    for y in range(H):
        y0 = y - 1 if y > 0 else y + 1
        y1 = y + 1 if y + 1 < H else y - 1
        for i in range(6):
            x = i if i < 3 else W - 6 + i
            if x < 0 or x >= W:
                continue
            green[y, x] = _held(raw, codes, y, y0, y1, x, 1)
            for c, cx, plane in ((0, rx, red), (2, 1 - rx, blue)):
                if (x & 1) == cx:
                    v = _held(raw, codes, y, y0, y1, x, c)
                elif x >= 1 and x + 1 < W:
                    v = (_held(raw, codes, y, y0, y1, x - 1, c) + _held(raw, codes, y, y0, y1, x + 1, c) + 1) >> 1
                else:
                    v = _held(raw, codes, y, y0, y1, x + 1 if x == 0 else x - 1, c)
                plane[y, x] = v


@njit(inline="always")
def _held(raw, codes, y, y0, y1, x, c):
    """Channel c in column x (which holds it) on row y: the site's sample, or the mean of the rows above and
    below."""
    if codes[y & 1, x & 1] == c:
        return np.int32(raw[y, x])
    return (np.int32(raw[y0, x]) + np.int32(raw[y1, x]) + 1) >> 1
