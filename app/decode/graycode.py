"""Gray-code decoder (multi-shot reference, and the correspondences calibration uses).

Frames per `core.patterns.graycode_patterns`: white, black, then for columns and then rows each bit
(MSB first) and its inverse. A pixel is valid where white - black is clearly above noise. Each bit
is `pattern > inverse` (robust to albedo and ambient light). Gray code moves the position by one
at any single bit error on a stripe edge, so there is no wrong-by-much value to guard against.

Sub-pixel: wherever the integer position steps by one between two neighbouring pixels, the
boundary q + 0.5 lies at the zero crossing of (pattern - inverse) of the one bit that flips between
q and q+1; positions are interpolated linearly between such boundaries along the row (columns)
or the column (rows).
"""

from __future__ import annotations

import itertools

import cv2
import numpy as np

from app.decode.stripemap import StripeMap
from core.errors import InputError


def _grey(img: np.ndarray) -> np.ndarray:
    # R + G + B as float32, added channel by channel (exact for 8 and 16 bits, as a sum over the last
    # axis is, in a fraction of its time: the calibration decodes 40 frames per pose)
    g = img[..., 0].astype(np.float32)
    g += img[..., 1]
    g += img[..., 2]
    return g / 257.0 if img.dtype == np.uint16 else g


def _smooth(nx: np.ndarray, nv: np.ndarray, h: int) -> tuple[np.ndarray, np.ndarray]:
    """Replace each boundary position by a straight-line fit x(v) over +-h neighbouring boundaries.

    Only boundaries that follow each other (positions one apart, a few pixels apart) are fitted
    together: single zero crossings are noisy, the surface is smooth over a few columns.
    """
    n = len(nx)
    if h <= 0 or n < 2 * h + 1:
        return nx, nv
    brk = np.flatnonzero((np.abs(np.diff(nv)) != 1) | (np.diff(nx) >= 8)) + 1
    gs = np.zeros(n, np.int64)  # group start / end (exclusive) of every node
    ge = np.zeros(n, np.int64)
    edges = np.concatenate([[0], brk, [n]])
    for a, b in itertools.pairwise(edges):
        gs[a:b], ge[a:b] = a, b
    i = np.arange(n)
    a0 = np.clip(i - h, gs, None)
    a1 = np.minimum(a0 + 2 * h + 1, ge)
    a0 = np.maximum(a1 - 2 * h - 1, gs)
    c = np.concatenate([[0.0], np.cumsum(nv)])
    cx = np.concatenate([[0.0], np.cumsum(nx)])
    cvv = np.concatenate([[0.0], np.cumsum(nv * nv)])
    cvx = np.concatenate([[0.0], np.cumsum(nv * nx)])
    m = (a1 - a0).astype(np.float64)
    sv, sx = c[a1] - c[a0], cx[a1] - cx[a0]
    svv, svx = cvv[a1] - cvv[a0], cvx[a1] - cvx[a0]
    den = svv - sv * sv / m
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(den > 0, (svx - sv * sx / m) / den, 0.0)
    fit = sx / m + slope * (nv - sv / m)
    out = np.where(m >= 3, fit, nx)
    return out, nv


def _subpixel(p: np.ndarray, valid: np.ndarray, diffs: np.ndarray, smooth: int = 2) -> np.ndarray:
    """p (H, W) integer positions along axis 1; diffs (nbits, H, W) with diffs[b] = bit b's pattern - inverse."""
    W = p.shape[1]
    out = np.where(valid, p.astype(np.float32), np.nan).astype(np.float32)
    dp = p[:, 1:] - p[:, :-1]
    trans = valid[:, :-1] & valid[:, 1:] & (np.abs(dp) == 1)
    ys, xs = np.nonzero(trans)
    q = np.minimum(p[ys, xs], p[ys, xs + 1])
    lowbit = (q + 1) & -(q + 1)  # the one Gray bit that flips between q and q+1
    bit = np.log2(lowbit).astype(np.int64)
    dl = diffs[bit, ys, xs]
    dr = diffs[bit, ys, xs + 1]
    ok = np.sign(dl) != np.sign(dr)
    with np.errstate(divide="ignore", invalid="ignore"):
        xz = np.where(ok, xs + dl / (dl - dr), xs + 0.5)
    val = q + 0.5
    starts = np.searchsorted(ys, np.arange(p.shape[0] + 1))  # ys is sorted by row
    for y in range(p.shape[0]):
        lo_i, hi_i = starts[y], starts[y + 1]
        if hi_i - lo_i < 2:
            continue
        nx, nv = xz[lo_i:hi_i], val[lo_i:hi_i]
        order = np.argsort(nx)
        nx, nv = _smooth(nx[order], nv[order], smooth)
        xr = np.arange(W, dtype=np.float64)
        # interpolate only between consecutive boundaries (one position apart, a few pixels apart)
        seg = np.clip(np.searchsorted(nx, xr) - 1, 0, len(nx) - 2)
        a, b = nx[seg], nx[seg + 1]
        va, vb = nv[seg], nv[seg + 1]
        good = (np.abs(vb - va) == 1) & (b - a < 8) & (xr >= a) & (xr <= b)
        interp = va + (xr - a) / np.maximum(b - a, 1e-6) * (vb - va)
        row = out[y]
        use = good & valid[y] & (np.abs(interp - p[y]) <= 1.0)
        row[use] = interp[use]
    return out


def decode_graycode(
    frames: list[np.ndarray],
    params: dict,
    kind: str = "column",
    t_valid: float = 15.0,
    t_bit: float = 0.15,
    t_spill: float = 0.25,
) -> np.ndarray:
    """Sub-pixel projector column (kind='column') or row ('row') per camera pixel, NaN = none.

    t_valid: minimum white - black, summed over R, G, B, in 8-bit steps; t_bit: a bit whose
    |pattern - inverse| is below this share of white - black is weak; t_spill: white - black below
    this share of its 7x7 neighbourhood's maximum is blur spilled into a shadow.
    """
    roles = params["frames"]
    if len(frames) != len(roles):
        raise InputError(f"Gray code needs {len(roles)} frames, got {len(frames)}")
    shape = frames[0].shape
    for f in frames:
        if f.shape != shape:
            raise InputError(f"Gray-code frames differ in size: {f.shape[:2]} vs {shape[:2]}")
    idx = {(r["kind"], r.get("bit"), r.get("inverse", False)): i for i, r in enumerate(roles)}
    white = _grey(frames[idx[("white", None, False)]])
    black = _grey(frames[idx[("black", None, False)]])
    contrast = white - black
    # light spilled into a shadow by lens blur is much weaker than its lit neighbours
    near_max = cv2.dilate(contrast, np.ones((7, 7), np.uint8))
    valid = (contrast > t_valid) & (contrast >= t_spill * near_max)
    nbits = int(params[f"{kind}_bits"])
    gray = np.zeros(shape[:2], np.int64)
    diffs = np.empty((nbits, *shape[:2]), np.float32)
    contrast = np.maximum(contrast, 1e-3)
    weak = np.zeros(shape[:2], np.int32)
    for b in range(nbits):
        d = _grey(frames[idx[(kind, b, False)]]) - _grey(frames[idx[(kind, b, True)]])
        diffs[b] = d
        gray |= (d > 0).astype(np.int64) << b
        weak += np.abs(d) < t_bit * contrast
    # Only one bit is ever on its own edge at a pixel (Gray code); more weak bits mean a pixel
    # straddling a shadow or depth edge, or light from elsewhere: no value.
    valid &= weak <= 1
    p = gray.copy()
    shift = gray >> 1
    while shift.any():
        p ^= shift
        shift >>= 1
    if kind == "row":
        return _subpixel(p.T.copy(), valid.T.copy(), np.ascontiguousarray(diffs.transpose(0, 2, 1))).T.copy()
    return _subpixel(p, valid, diffs)


class GrayCodeDecoder:
    """Columns from a Gray-code frame set, masked to the depth range's columns when given."""

    def __init__(self, pattern_params: dict, column_range: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        self.params = pattern_params
        self.shots = len(pattern_params["frames"])
        self.column_range = column_range

    def decode(self, frames: list[np.ndarray]) -> StripeMap:
        col = decode_graycode(frames, self.params, "column")
        if self.column_range is not None:
            lo, hi = self.column_range
            col[~((col >= lo) & (col <= hi))] = np.nan
        conf = np.isfinite(col).astype(np.float32)
        return StripeMap(col, conf, stripe_width=1, period=0)
