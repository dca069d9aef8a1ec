"""Motion: the older frame of a two-shot pair, repaired where the scene moved since the frame before it.

A two-shot pair decodes from the sign of frame2 - frame1, which holds only while the scene is still. Where the
newest frame differs from the previous frame of the same pattern (two frames earlier) by more than noise and a
share of the local stripe contrast, the scene moved: there the older frame is replaced by the newest frame's own
inverse about its local envelope, lin(older') = hi + lo - lin(newest), with hi and lo the largest and smallest
linear value of the newest frame in a window along the row (MotionParams). The pair's difference is then twice
the newest frame's distance from its local midpoint: the newest frame decodes alone, as the one-shot code it is,
while still pixels keep the pair's robustness to surface colour and ambient light. Elsewhere the older frame is
left as it was, bit for bit, so a still scene decodes exactly as without this stage.

`app/decode/motion.py` holds the parameters and a plain numpy statement of the same computation (the tests
compare both).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.differences import PAIR_ENTRIES


@njit(cache=True, nogil=True, error_model="numpy")
def repair_older(
    frames: tuple,
    tables: tuple,
    watched: np.ndarray,
    limits: np.ndarray,
    radii: np.ndarray,
    spread: int,
    out: np.ndarray,
) -> int:
    """Write the repaired older frame into out (the frames' shape and dtype) and return the moving pixels.

    frames: (newest, older, previous), (H, W, 3) frames of one dtype; previous saw the newest frame's pattern.
    tables: (lin, dlin, pairs, inverse, grid): the camera's linearisation and its noise slope (3, levels) float32
    (app.decode.colour.linearisation); for 8-bit frames the pair table of app.decode.fast.pair_tables (one gather
    for a change and its noise slopes), else an empty one; linear value -> nearest raw level per channel
    (app.decode.motion.inverse_table). watched: the camera channels (int64) whose change marks motion (the
    pattern's). limits: float32 (share of the local contrast, multiple of the noise slopes, floor in linear 8-bit
    units) a change must exceed, then the share of the wide window's contrast the narrow window must keep to be
    used. radii: int64 (narrow, wide) half-widths of the envelope windows along the row; spread: how far along the
    row a moving pixel's mark reaches."""
    newest, older, previous = frames
    H, W, C = newest.shape
    rows = np.empty((5 * C + 8, W), np.float32)  # the row loop's scratch rows
    flat = (older.reshape(H, W * C), out.reshape(H, W * C))  # (the rows' copy as one vector loop)
    return _repair_rows((newest, previous), tables, watched, limits, radii, spread, rows, flat, out)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _repair_rows(frames, tables, watched, limits, radii, spread, rows, flat, out):
    """repair_older's loop over the rows, without reference counting (its arrays all belong to the caller)."""
    newest, previous = frames
    lin, dlin, pairs, inverse, grid = tables
    H, W, C = newest.shape
    rel, noise_k, floor, narrow_share = limits[0], limits[1], limits[2], limits[3]
    ln = rows[0:C]  # the newest frame's linear values, channel-planar
    hi = rows[C : 2 * C]  # their extremes over the envelope window
    lo = rows[2 * C : 3 * C]
    spans = rows[3 * C : 3 * C + 4]
    wide_hi = rows[3 * C + 4]  # the extremes over the wide window, one channel
    wide_lo = rows[3 * C + 5]
    changed = rows[3 * C + 6]  # 1 where the pixel changed, else 0 (float32 rows: their max and min vectorise)
    moving = rows[3 * C + 7]
    changes = rows[3 * C + 8 : 4 * C + 8]  # |newest - previous|, linear, per watched channel
    slopes = rows[4 * C + 8 : 5 * C + 8]  # the newest and the previous frame's noise slopes summed, per watched channel
    pair_halves = pairs.view(np.float32)
    shared_pairs = pairs.shape[0] == PAIR_ENTRIES  # (one pair table for the three channels)
    older_flat, out_flat = flat
    n_moving = 0
    for y in range(H):
        _copy_into(older_flat[y], out_flat[y])
        # the changes first, and the test without its share of the local contrast: a row in which no two pixels
        # pass it has no moving pixel, and needs no envelope (most rows of a still scene)
        candidates = 0
        for i in range(watched.shape[0]):
            c = watched[i]
            change, slope_sum = changes[i], slopes[i]
            # (the gathers, then the arithmetic over plain rows, which vectorises)
            if pairs.shape[0] >= PAIR_ENTRIES:  # 8-bit: (lin[n] - lin[p], dlin[n] + dlin[p]) in one gather
                base = 0 if shared_pairs else c * PAIR_ENTRIES
                for x in range(W):
                    e = 2 * (base + 256 * np.int64(previous[y, x, c]) + np.int64(newest[y, x, c]))
                    change[x] = abs(pair_halves[e])
                    slope_sum[x] = pair_halves[e + 1]
            else:
                table = lin[c]
                slope = dlin[c]
                for x in range(W):
                    n = newest[y, x, c]
                    p = previous[y, x, c]
                    change[x] = abs(table[n] - table[p])
                    slope_sum[x] = slope[n] + slope[p]
            for x in range(W):
                candidates += 1 if change[x] > max(noise_k * slope_sum[x], floor) else 0
        if candidates < 2:
            continue
        for c in range(C):
            table = lin[c]
            lnc, hic, loc = ln[c], hi[c], lo[c]
            for x in range(W):
                lnc[x] = table[newest[y, x, c]]
            # the narrow window where it holds both levels of the channel (its contrast a share of the wide
            # window's), else the wide one: a narrow window reaches across fewer albedo and depth edges
            _window_extremes(lnc, lnc, radii[0], hic, loc, spans)
            _window_extremes(lnc, lnc, radii[1], wide_hi, wide_lo, spans)
            for x in range(W):
                narrow = hic[x] - loc[x] >= narrow_share * (wide_hi[x] - wide_lo[x])
                hic[x] = hic[x] if narrow else wide_hi[x]
                loc[x] = loc[x] if narrow else wide_lo[x]
        _fill(changed, 0.0)
        for i in range(watched.shape[0]):
            c = watched[i]
            change, slope_sum = changes[i], slopes[i]
            hic, loc = hi[c], lo[c]
            for x in range(W):
                limit = max(rel * (hic[x] - loc[x]), noise_k * slope_sum[x], floor)
                u = np.float32(1.0) if change[x] > limit else np.float32(0.0)
                changed[x] = u if u > changed[x] else changed[x]
        # a change counts where a neighbour along the row changed too: noise is per pixel, a moving edge is not
        _fill(moving, 0.0)
        _max_inplace(moving[: W - 1], changed[1:])
        _max_inplace(moving[1:], changed[: W - 1])
        _min_inplace(changed, moving)
        _copy_into(changed, moving)
        for o in range(1, min(spread, W - 1) + 1):
            _max_inplace(moving[: W - o], changed[o:])
            _max_inplace(moving[o:], changed[: W - o])
        for x in range(W):
            if moving[x] == 0:
                continue
            n_moving += 1
            for c in range(C):
                out[y, x, c] = inverse[c, inverse_bin(hi[c, x] + lo[c, x] - ln[c, x], grid)]
    return n_moving


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _window_extremes(up, down, radius, hi, lo, spans):
    """hi[x] = max(up[x - radius : x + radius + 1]) and lo[x] = min(down[...]), the window clipped at the row's ends.
    Inside the row from spans doubled to the largest power of two p in the window (a sparse table: two reads per
    pixel; spans (4, W) float32 scratch, each pass from one row into another); the pixels whose window the row's
    ends cut short are done directly. The loops read through views from each offset: an index x + s of unknown
    sign would get numba's negative-index fix per element and stay scalar."""
    W = up.shape[0]
    p = 1
    while 2 * p <= 2 * radius + 1:
        p *= 2
    a_hi, a_lo, b_hi, b_lo = spans[0], spans[1], spans[2], spans[3]
    _copy_into(up, a_hi)
    _copy_into(down, a_lo)
    s = 1
    in_a = True  # which pair of rows holds the spans so far (named rows, no swapped references: the loops vectorise)
    while s < p and s < W:  # the spans over [x, x + 2 s - 1], clipped at the row's end
        n = W - s
        if in_a:
            _max_into(a_hi[:n], a_hi[s:], b_hi[:n])
            _min_into(a_lo[:n], a_lo[s:], b_lo[:n])
            _copy_into(a_hi[n:], b_hi[n:])
            _copy_into(a_lo[n:], b_lo[n:])
        else:
            _max_into(b_hi[:n], b_hi[s:], a_hi[:n])
            _min_into(b_lo[:n], b_lo[s:], a_lo[:n])
            _copy_into(b_hi[n:], a_hi[n:])
            _copy_into(b_lo[n:], a_lo[n:])
        in_a = not in_a
        s *= 2
    n = W - 2 * radius  # pixels whose whole window is inside the row
    if n > 0:
        shift = 2 * radius - p + 1  # the second span's start, from the window's first pixel
        if in_a:
            _max_into(a_hi[:n], a_hi[shift : shift + n], hi[radius : radius + n])
            _min_into(a_lo[:n], a_lo[shift : shift + n], lo[radius : radius + n])
        else:
            _max_into(b_hi[:n], b_hi[shift : shift + n], hi[radius : radius + n])
            _min_into(b_lo[:n], b_lo[shift : shift + n], lo[radius : radius + n])
    ends = (range(0, min(radius, W)), range(max(W - radius, min(radius, W)), W))
    for end in ends:  # the pixels whose window the row's ends cut short
        _window_direct(up, down, radius, hi, lo, end)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _window_direct(up, down, radius, hi, lo, pixels):
    W = up.shape[0]
    for x in pixels:
        first = max(x - radius, 0)
        last = min(x + radius, W - 1)
        u = up[first]
        v = down[first]
        for i in range(first + 1, last + 1):
            u = up[i] if up[i] > u else u
            v = down[i] if down[i] < v else v
        hi[x] = u
        lo[x] = v


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _max_into(a, b, out):
    for x in range(out.shape[0]):
        u, v = a[x], b[x]
        out[x] = u if u > v else v


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _min_into(a, b, out):
    for x in range(out.shape[0]):
        u, v = a[x], b[x]
        out[x] = u if u < v else v


# In place, not _max_into(a, b, a): the vectoriser's run-time overlap check between a store and a load fails for
# one array as both, and the loop then runs scalar.
@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _max_inplace(a, b):
    for x in range(a.shape[0]):
        u, v = a[x], b[x]
        a[x] = u if u > v else v


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _min_inplace(a, b):
    for x in range(a.shape[0]):
        u, v = a[x], b[x]
        a[x] = u if u < v else v


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _copy_into(a, out):
    for x in range(out.shape[0]):
        out[x] = a[x]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _fill(out, value):
    for x in range(out.shape[0]):
        out[x] = value


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def inverse_bin(value: np.float32, grid: np.ndarray) -> int:
    """The bin of the inverse table (motion.inverse_table) nearest to a linear value: grid = (first bin's value,
    bins per linear unit, number of bins), float32; values outside are clamped to the first or last bin."""
    b = int((value - grid[0]) * grid[1] + np.float32(0.5))
    return min(max(b, 0), int(grid[2]) - 1)
