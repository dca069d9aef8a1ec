"""Column write (paper section 3): a chain's pixels get projector columns interpolated between its nodes.

Each segment between neighbouring nodes is a line (column at the chain's first pixel, slope), computed once per
chain; each pixel then gets its segment's line (segment_values), so that the loop that interpolates reads plain
rows and is vectorised. Pixels are kept within the chain's column span and, with a depth range, inside their
pixel's allowed interval. While writing, the chain's pixels and its vertical votes against the row above are
counted (see check.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import ChainMap, LabelScratch, LabelSettings
from app.decode.primitives import fill_eight, gather

# Pixels beyond a chain's outer stripe edges keep a value up to this many stripes out (the end stripe's
# own pixels; its far side is not measured, so beyond half a stripe is the blur of a shadow edge).
END_EXT = 0.5


@njit(cache=True, nogil=True, inline="always")
def _column_at(q, line, lo_v, hi_v, use_range, lo, hi, y, xx):
    """The column of pixel xx = xa + q on its segment's line (line: float32 (column at xa, slope), interleaved),
    and whether it is kept: within the chain's column span [lo_v, hi_v] and, with use_range, the pixel's
    depth-range interval. float32 throughout: twice the lanes of float64, and the columns are stored as float32."""
    # q < 2**24 through int32: exact, and int64 -> float has no vector instruction before AVX-512
    v = line[2 * q] + np.float32(np.int32(q)) * line[2 * q + 1]
    ok = (v >= lo_v) & (v <= hi_v)
    if use_range:
        ok &= (v >= lo[y, xx]) & (v <= hi[y, xx])
    return v, ok


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def segment_values(
    nx: np.ndarray,
    nn: int,
    xa: int,
    nxp: int,
    first: np.ndarray,
    seg_of: np.ndarray,
    vals: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[q] = vals[the segment of pixel xa + q] (q < nxp), the segments being those between the chain's nodes
    nx[:nn] (increasing): the one after the last interior node left of the pixel (the first segment extends
    left, the last right), i.e. the last interior node r whose first pixel right of it, s_r, is <= the pixel
    (s never decreases). first: scratch for nn values; seg_of (integer) scratch and out need room for nxp + 8."""
    short = True
    for r in range(1, nn - 1):
        # clamped in float (NaN -> 0), then converted to int32: float -> int64 has no vector instruction before
        # AVX-512, and the clamped value is a small integer, so this equals clamping int(floor) + 1 - xa
        f = np.floor(nx[r]) + np.float64(1 - xa)
        f = f if f > 0.0 else 0.0
        f = f if f < nxp else np.float64(nxp)
        first[r] = np.int32(f)
    for r in range(1, nn - 2):
        short &= first[r + 1] - first[r] <= 8
    if short:
        # segments of at most 8 pixels (all but freak chains): each node writes its segment's value over the 8
        # pixels from its s_r, in order, so the next node overwrites the rest (one vector store per node, no
        # per-pixel segment index)
        s1 = first[1] if nn > 2 else nxp
        v = vals[0]
        for q in range(s1):
            out[q] = v
        for r in range(1, nn - 1):
            fill_eight(out, first[r], vals[r])
        if nn > 2:
            v = vals[nn - 2]
            for q in range(first[nn - 2] + 8, nxp):
                out[q] = v
        return
    for q in range(nxp + 1):
        seg_of[q] = 0
    for r in range(1, nn - 1):
        seg_of[first[r]] += 1
    seg = 0
    for q in range(nxp):
        seg += seg_of[q]
        seg_of[q] = seg
    gather(out, vals, seg_of, nxp)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def pixel_lines(nn: int, xa: int, nxp: int, shift: float, scratch: LabelScratch) -> None:
    """scratch.px_halves = the line (column, slope: a float32 pair) of each of the chain's nxp pixels from xa,
    from its nn nodes shifted by the copy's shift."""
    nx = scratch.nodes_x
    nv = scratch.nodes_v
    lines = scratch.seg_halves
    for r in range(nn - 1):
        slope = (nv[r + 1] - nv[r]) / (nx[r + 1] - nx[r])
        lines[2 * r] = np.float32(nv[r] + shift + (xa - nx[r]) * slope)
        lines[2 * r + 1] = np.float32(slope)
    # the pairs copied whole, as int64
    segment_values(nx, nn, xa, nxp, scratch.seg_first, scratch.seg_of, scratch.seg_lines, scratch.px_lines)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def write_chain(
    y: int,
    c: int,
    row_first: int,
    xa: int,
    xb: int,
    lo_v: np.float32,
    hi_v: np.float32,
    line: np.ndarray,
    settings: LabelSettings,
    lo: np.ndarray,
    hi: np.ndarray,
    out: ChainMap,
) -> None:
    """Write chain c's columns (pixels xa .. xb of row y, lines line, span [lo_v, hi_v]) into out.

    When out.npx has room for chain c, its pixels are counted into npx[c] and, against row y - 1 (labelled, not
    yet checked), its vertical votes within tol into agree[c] and disagree[c], as row_votes would count the
    finished row: a pixel two chains share is counted for the later one, which writes it last."""
    use_range = settings.use_range
    col, chain, agree, disagree, npx, span, _ = out
    cy = y % chain.shape[0]
    # 0 <= xa <= xb < W (the caller clamps them), restated for the compiler, which optimises this function before
    # it is inlined: without the bounds every pixel index gets numba's negative-index fix and the loops stay scalar
    xa = max(xa, 0)
    xb = min(xb, col.shape[1] - 1)
    nxp = xb - xa + 1
    if c >= npx.shape[0]:
        for q in range(nxp):
            xx = xa + q
            v, ok = _column_at(q, line, lo_v, hi_v, use_range, lo, hi, y, xx)
            if ok:
                col[y, xx] = v
                chain[cy, xx] = c
        return
    # the row above is read at y - 1 >= 0 and its votes masked at y = 0 (one loop, vectorised)
    up = max(y - 1, 0)
    cu = up % chain.shape[0]
    above = y > 0
    tol32 = np.float32(settings.tol)
    # the zero-crossing runs of neighbouring stripes share a pixel when the crossing falls exactly on it, so the
    # row's previous chain may own this chain's first pixel: if this chain takes it, that pixel's count and vote
    # move here
    shared = -1
    shared_col = np.float32(0.0)
    if c > row_first and c - 1 < span.shape[0]:
        pe = span[c - 1, 1]
        if pe >= xa and chain[cy, pe] == c - 1:
            shared = pe
            shared_col = col[y, pe]
    # the counts in int32, the lanes of the float32 columns (numba widens int32 arithmetic to int64)
    n = np.int32(0)
    ag = np.int32(0)
    dg = np.int32(0)
    for q in range(nxp):
        xx = xa + q
        v32, ok = _column_at(q, line, lo_v, hi_v, use_range, lo, hi, y, xx)
        if ok:
            col[y, xx] = v32
            chain[cy, xx] = c
        n = np.int32(n + ok)
        pair = ok & above & (chain[cu, xx] >= 0)
        close = abs(col[up, xx] - v32) <= tol32
        ag = np.int32(ag + (pair & close))
        dg = np.int32(dg + (pair & (not close)))
    npx[c] = n
    agree[c] = ag
    disagree[c] = dg
    if shared >= 0 and chain[cy, shared] == c:
        npx[c - 1] -= 1
        if above and chain[cu, shared] >= 0:
            if abs(col[up, shared] - shared_col) <= tol32:
                agree[c - 1] -= 1
            else:
                disagree[c - 1] -= 1
