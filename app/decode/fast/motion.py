"""Motion: the older frame of a two-shot pair, repaired where the scene moved since the frame before it.

A two-shot pair decodes from the sign of frame2 - frame1, which holds only while the scene is still. Where the
newest frame differs from the previous frame of the same pattern (two frames earlier) by more than noise and a share
of the local stripe contrast, the scene moved: there the older frame is replaced by the newest frame's own inverse
about its local envelope, lin(older') = hi + lo - lin(newest), with hi and lo the largest and smallest linear value
of the newest frame in a window along the row (MotionParams); or, where the newest and the older frame's local means
along the row (over a window and each of its halves) agree, hi + lo = their sum. The pair's difference is then twice
the newest frame's distance from its local midpoint: the newest frame decodes alone, as the one-shot code it is,
while still pixels keep the pair's robustness to surface colour and ambient light. Elsewhere the older frame is left
as it was, bit for bit, so a still scene decodes exactly as without this stage.

`app/decode/motion.py` holds the parameters and a plain numpy statement of the same computation (the tests
compare both).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.differences import PAIR_ENTRIES
from app.decode.primitives import gather

MEAN_SCALE = 16  # the local sums' quantisation: steps of 1 / MEAN_SCALE linear 8-bit units (int32 sums, exact)


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
    tables: (lin, dlin, pairs, inverse, grid, quantised_lin, quiet): the camera's linearisation and its noise slope (3,
    levels) float32 (app.decode.colour.linearisation); for 8-bit frames the pair table of app.decode.fast.pair_tables
    (one gather for a change and its noise slopes), else an empty one; linear value -> nearest raw level per channel
    (app.decode.motion.inverse_table); the linearisation quantised as the local sums' terms (quantised_table); per
    channel the raw distance within which no change passes the change test (quiet_distances, int64, -1 where unknown).
    watched: the camera channels (int64) whose change marks motion (the pattern's). limits: float32 (share of the local
    contrast, multiple of the noise slopes, floor in linear 8-bit units) a change must exceed, then the share of the
    wide window's contrast the narrow window must keep to be used, then the share of their sum and the floor within
    which the two frames' local means must agree to be used. radii: int64 (narrow, wide) half-widths of the envelope
    windows along the row, then that of the local means; spread: how far along the row a moving pixel's mark reaches."""
    newest, older, previous = frames
    H, W, C = newest.shape
    rows = _scratch_rows(C, W)
    per_pixel = np.empty((4, W), np.float32)
    _window_constants(W, radii[2], limits[5], per_pixel)
    # table indices and gathered values: C rows of int32, a row of int64 (a pair table's entries); the newest and the
    # older frame's quantised values along the row and their running sums, int32 (exact: any start gives the same
    # window sums); per pixel of a row, the local means' floors (window, left half, right half) in sums' units and
    # the window's reciprocal count (the window clipped at the row's ends)
    quantised_rows = (
        np.empty(W + 1, np.int32),
        np.empty(W + 1, np.int32),
        np.empty(W + 1, np.int32),
        np.empty(W + 1, np.int32),
    )
    lookups = (np.empty((C, W), np.int32), np.empty(W, np.int64), quantised_rows, per_pixel)
    # the rough change test per raw value of a row (a byte each, whole words to scan), its threshold per raw value
    # (the channel's quiet distance; never passed in a channel not watched) and the row's candidates
    rough = np.zeros(((W * C + 7) // 8) * 8, np.uint8)
    quiet = tables[6]
    exact = True  # whether the rough test is the change test itself (no quiet distance known)
    for i in range(watched.shape[0]):
        exact &= quiet[watched[i]] < 0
    beyond = np.empty(W * C, newest.dtype)
    never = np.iinfo(newest.dtype).max
    for x in range(W):
        for c in range(C):
            beyond[x * C + c] = never
        for i in range(watched.shape[0]):
            beyond[x * C + watched[i]] = min(max(quiet[watched[i]], 0), never)
    marks = np.zeros(((W + 7) // 8) * 8, np.uint8)  # the row's paired candidates, a byte each
    distance = np.empty(W * C, newest.dtype)  # the raw change per value of a row
    scan = (rough, rough.view(np.uint64), beyond, distance, np.empty(W, np.int64), exact, marks, marks.view(np.uint64))
    flat = (older.reshape(H, W * C), out.reshape(H, W * C), newest.reshape(H, W * C), previous.reshape(H, W * C))
    return _repair_rows(
        (newest, previous, older, out), tables, watched, limits, radii, spread, rows, lookups, flat, scan
    )


@njit(cache=True, nogil=True, error_model="numpy")
def _scratch_rows(C, W):
    """The segments' float32 scratch rows, each named row (or per-channel block) its own allocation: the vectoriser
    cannot separate stores into two rows of one array from its other accesses (its overlap check then sends the loop
    to its scalar form), while rows of distinct allocations get a check that passes."""
    f = np.float32
    return (
        np.empty((C, W), f),  # 0 ln: the newest frame's linear values, channel-planar
        np.empty((C, W), f),  # 1 hi: their extremes over the envelope window
        np.empty((C, W), f),  # 2 lo
        (np.empty(W, f), np.empty(W, f), np.empty(W, f), np.empty(W, f)),  # 3 spans: the envelopes' sparse table
        np.empty(W, f),  # 4 wide_hi: the extremes over the wide window, one channel
        np.empty(W, f),  # 5 wide_lo
        np.empty(W, f),  # 6 changed: 1 where the pixel changed, else 0 (float32: their max and min vectorise)
        np.empty(W, f),  # 7 moving
        np.empty((C, W), f),  # 8 changes: |newest - previous|, linear, per watched channel
        np.empty((C, W), f),  # 9 slopes: the newest and the previous frame's noise slopes summed, per watched channel
        np.empty((C, W), f),  # 10 sums_new: the newest frame's local sums (quantised, exact in float32), per channel
        np.empty((C, W), f),  # 11 sums_old: the older frame's
        np.empty(W, f),  # 12 agree: 1 where the two frames' local means agree in every watched channel, else 0
    )


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _repair_rows(frames, tables, watched, limits, radii, spread, rows, lookups, flat, scan):
    """repair_older's loop over the rows, without reference counting (its arrays all belong to the caller).

    A pixel moves only within spread of a changed pixel whose neighbour along the row changed too, and a changed
    pixel passes the change test without its share of the local contrast (a candidate): so only pairs of
    neighbouring candidates start work, over segments of the row around them. Within a segment every result is
    the whole row's: its windows reach at most radii beyond it into the row (clipped at the row's ends, not the
    segment's), and its ends lie at least max(spread, 1) from its pairs, so no mark or neighbour test crosses
    them."""
    W = frames[0].shape[1]
    older_flat, out_flat = flat[0], flat[1]
    xs = scan[4]
    pad = max(spread, 1)
    join = 2 * max(radii[0], radii[1], radii[2])  # segments closer than this share one window reach
    n_moving = 0
    for y in range(older_flat.shape[0]):
        _copy_into(older_flat[y], out_flat[y])
        m = _row_candidates(frames, tables, watched, limits, flat, scan, rows, lookups, y)
        if m < 0:  # a dense row: one segment over all its paired candidates
            a, b = max(xs[0] - pad, 0), min(xs[1] + pad + 1, W)
            n_moving += _repair_span(frames, tables, watched, limits, radii, spread, rows, lookups, flat, y, a, b)
            continue
        a, b = -1, -1
        for k in range(m):
            x = xs[k]
            if a >= 0 and x - pad <= b + join:
                b = min(x + pad + 1, W)
                continue
            if a >= 0:
                n_moving += _repair_span(frames, tables, watched, limits, radii, spread, rows, lookups, flat, y, a, b)
            a, b = max(x - pad, 0), min(x + pad + 1, W)
        if a >= 0:
            n_moving += _repair_span(frames, tables, watched, limits, radii, spread, rows, lookups, flat, y, a, b)
    return n_moving


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _row_candidates(frames, tables, watched, limits, flat, scan, rows, lookups, y):
    """Row y's paired candidates (pixels whose change against the previous frame passes the test without its share of
    the local contrast in a watched channel, beside another such pixel), in increasing order into scan's candidate
    row; returns how many, or -1 for a row where more than a quarter of the pixels are (only the first and the last
    then, in the candidate row's first two entries: one segment covers them all). For 8-bit frames a rough test
    first, the raw change beyond the channel's quiet distance (a byte compare over the row's raw values): a row where
    no value passes it has none. Else the test over the whole row in vector loops, as _repair_span's (the same table
    reads, the same float32 values)."""
    newest, previous = frames[0], frames[1]
    lin, dlin, pairs = tables[0], tables[1], tables[2]
    noise_k, floor = limits[1], limits[2]
    rough, words, beyond, distance, xs, exact, marks, mark_words = scan
    W, C = newest.shape[1], newest.shape[2]
    if not exact:
        new_row, previous_row = flat[2][y], flat[3][y]
        # the distances stored in the frames' dtype, then compared: both loops run in the frames' lanes (one loop
        # or a select of two differences computes in int64 lanes, on AVX2 targets at least)
        for i in range(W * C):
            distance[i] = max(new_row[i], previous_row[i]) - min(new_row[i], previous_row[i])
        for i in range(W * C):
            rough[i] = 1 if distance[i] > beyond[i] else 0
        any_rough = 0
        for k in range(words.shape[0]):
            any_rough |= words[k]
        if any_rough == 0:
            return 0
    candidate = rows[6]
    index, entries = lookups[0], lookups[1]
    entry_halves = entries.view(np.float32)
    shared_pairs = pairs.shape[0] == PAIR_ENTRIES
    _fill(candidate, 0.0)
    for i in range(watched.shape[0]):
        c = watched[i]
        change, slope_sum = rows[8][i], rows[9][i]  # (kept for the row's segments)
        if pairs.shape[0] >= PAIR_ENTRIES:  # 8-bit: (lin[n] - lin[p], dlin[n] + dlin[p]) in one gather
            base = np.int32(0 if shared_pairs else c * PAIR_ENTRIES)
            at = index[0]
            p_row, n_row = flat[3][y], flat[2][y]
            if C == 3:  # (a constant stride: the loop vectorises)
                p_row, n_row = p_row[c:], n_row[c:]
                for x in range(W):
                    at[x] = base + (np.int32(p_row[3 * x]) << 8) + np.int32(n_row[3 * x])
            else:
                for x in range(W):
                    at[x] = base + (np.int32(p_row[C * x + c]) << 8) + np.int32(n_row[C * x + c])
            gather(entries, pairs, at, W)
            for x in range(W):
                change[x] = abs(entry_halves[2 * x])
                slope_sum[x] = entry_halves[2 * x + 1]
        else:
            table, slope = lin[c], dlin[c]
            for x in range(W):
                u, v = newest[y, x, c], previous[y, x, c]
                change[x] = abs(table[u] - table[v])
                slope_sum[x] = slope[u] + slope[v]
        for x in range(W):
            u = np.float32(1.0) if change[x] > max(noise_k * slope_sum[x], floor) else np.float32(0.0)
            candidate[x] = u if u > candidate[x] else candidate[x]
    # paired: a candidate with a candidate beside it (only such a pixel can count as changed)
    if W > 1:
        marks[0] = 1 if candidate[0] != 0 and candidate[1] != 0 else 0
        marks[W - 1] = 1 if candidate[W - 1] != 0 and candidate[W - 2] != 0 else 0
    else:
        marks[0] = 0
    _mark_paired(candidate[1 : W - 1], candidate[: W - 2], candidate[2:], marks[1 : W - 1])
    count = 0
    for x in range(W):
        count += np.int64(marks[x])
    if count == 0:
        return 0
    if 4 * count > W:  # dense: only the first and the last, in xs[0] and xs[1] (no per-pixel scan), and -1
        first, last = 0, W - 1
        while marks[first] == 0:
            first += 1
        while marks[last] == 0:
            last -= 1
        xs[0], xs[1] = first, last
        return -1
    m = 0
    for k in range(mark_words.shape[0]):
        if mark_words[k] == 0:
            continue
        for x in range(8 * k, 8 * k + 8):
            if marks[x] != 0:
                xs[m] = x
                m += 1
    return m


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _channel_into(row, c, C, first, n, out):
    """out[x] = channel c of pixel first + x of a frame row flattened (C channels a pixel), for x < n. Read through
    a view from the first value: three-dimensional indexing, or an offset of unknown sign, keeps the loop scalar."""
    src = row[C * first + c :]
    if C == 3:  # (a constant stride: the loop vectorises)
        for x in range(n):
            out[x] = src[3 * x]
    else:
        for x in range(n):
            out[x] = src[C * x]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _mark_paired(centre, left, right, out):
    for x in range(out.shape[0]):
        out[x] = 1 if centre[x] != 0 and (left[x] != 0 or right[x] != 0) else 0


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _repair_span(frames, tables, watched, limits, radii, spread, rows, lookups, flat, y, a, b):
    """The repair of row y's pixels [a, b) (a segment around neighbouring candidates); returns its moving pixels.
    Table reads go through `gather` (indices first, into plain rows): the loops around them then vectorise."""
    newest, out = frames[0], frames[3]
    lin, inverse, grid, quantised_lin = tables[0], tables[3], tables[4], tables[5]
    W, C = newest.shape[1], newest.shape[2]
    rel, noise_k, floor, narrow_share = limits[0], limits[1], limits[2], limits[3]
    mean_share = limits[4]
    ln, hi, lo, spans, wide_hi, wide_lo = rows[0], rows[1], rows[2], rows[3], rows[4], rows[5]
    changed, moving, changes, slopes = rows[6], rows[7], rows[8], rows[9]
    sums_new, sums_old, agree = rows[10], rows[11], rows[12]
    index, quantised_rows, per_pixel = lookups[0], lookups[2], lookups[3]
    qn, qo, sn, so = quantised_rows[0], quantised_rows[1], quantised_rows[2], quantised_rows[3]
    n = b - a
    reach = max(radii[0], radii[1])
    e, f = max(a - reach, 0), min(b + reach, W)
    rm = radii[2]
    s0, g = max(a - rm, 0), min(b + rm, W)  # the local sums' reach
    agree_ab = agree[a:b]
    _fill(agree_ab, 1.0)
    e2, f2 = min(e, s0), max(f, g)  # (the pixels of both reaches: one gather)
    for c in range(C):
        lnc, hic, loc = ln[c, e:f], hi[c, e:f], lo[c, e:f]
        at = index[c, e2:f2]
        _channel_into(flat[2][y], c, C, e2, f2 - e2, at)
        gather(ln[c, e2:f2], lin[c], at, f2 - e2)
        # the narrow window where it holds both levels of the channel (its contrast a share of the wide
        # window's), else the wide one: a narrow window reaches across fewer albedo and depth edges
        spans_ef = (spans[0][e:f], spans[1][e:f], spans[2][e:f], spans[3][e:f])
        _envelopes(lnc, radii[0], radii[1], hic, loc, wide_hi[e:f], wide_lo[e:f], spans_ef, (e == 0, f == W))
        hic, loc, whi, wlo = hi[c, a:b], lo[c, a:b], wide_hi[a:b], wide_lo[a:b]
        for x in range(n):
            narrow = hic[x] - loc[x] >= narrow_share * (whi[x] - wlo[x])
            hic[x] = hic[x] if narrow else whi[x]
            loc[x] = loc[x] if narrow else wlo[x]
        # the local sums of the newest and the older frame over the window clipped at the row's ends
        m = g - s0
        at = index[c, :m]
        _channel_into(flat[0][y], c, C, s0, m, at)
        gather(qo, quantised_lin[c], at, m)  # (the older frame's linear values serve only these sums)
        _quantise(ln[c, s0:g], qn)
        _running_sums(qn, qo, m, sn, so)
        mn, mo = sums_new[c, a:b], sums_old[c, a:b]
        # Where the two frames' local means agree (the surface's level unchanged across the window) their sum
        # is the channel's local sum of both levels, balanced whatever the code: it replaces the envelope's
        # hi + lo there. The means over the window's two halves must agree too: a silhouette or an albedo edge
        # that moved inside the window changes one half's level while the whole's may stay within the share.
        if _is_watched(watched, c):
            # the halves [x - rm, x] and [x, x + rm], and the window as their sum less pixel x (exact integers)
            halves = (spans[0][a:b], spans[1][a:b], spans[2][a:b], spans[3][a:b])  # (free until the next channel)
            _window_sums(sn, s0, a, b, -rm, 0, W, halves[0])
            _window_sums(so, s0, a, b, -rm, 0, W, halves[1])
            _window_sums(sn, s0, a, b, 0, rm, W, halves[2])
            _window_sums(so, s0, a, b, 0, rm, W, halves[3])
            # (1-D rows: the 2-D view per_pixel[:3, a:b] has a run-time row stride, and keeps the loop scalar)
            floors = (per_pixel[0, a:b], per_pixel[1, a:b], per_pixel[2, a:b])
            _agree_halves(halves, qn[a - s0 :], qo[a - s0 :], mean_share, floors, mn, mo, agree_ab)
        else:
            _window_sums(sn, s0, a, b, -rm, rm, W, mn)
            _window_sums(so, s0, a, b, -rm, rm, W, mo)
    changed_ab, moving_ab = changed[a:b], moving[a:b]
    _fill(changed_ab, 0.0)
    for i in range(watched.shape[0]):  # (the changes and their noise slopes: _row_candidates's, over the row)
        c = watched[i]
        change, slope_sum = changes[i, a:b], slopes[i, a:b]
        hic, loc = hi[c, a:b], lo[c, a:b]
        for x in range(n):
            limit = max(rel * (hic[x] - loc[x]), noise_k * slope_sum[x], floor)
            u = np.float32(1.0) if change[x] > limit else np.float32(0.0)
            changed_ab[x] = u if u > changed_ab[x] else changed_ab[x]
    # a change counts where a neighbour along the row changed too: noise is per pixel, a moving edge is not
    _fill(moving_ab, 0.0)
    _max_inplace(moving_ab[: n - 1], changed_ab[1:])
    _max_inplace(moving_ab[1:], changed_ab[: n - 1])
    _min_inplace(changed_ab, moving_ab)
    _copy_into(changed_ab, moving_ab)
    for o in range(1, min(spread, n - 1) + 1):
        _max_inplace(moving_ab[: n - o], changed_ab[o:])
        _max_inplace(moving_ab[o:], changed_ab[: n - o])
    # every pixel's inverse computed and kept where the pixel moves (a select, not a branch: vectorised)
    last_bin = np.float32(grid[2] - 1)
    first, per_unit = grid[0], grid[1]
    for c in range(C):
        hic, loc, lnc, at = hi[c, a:b], lo[c, a:b], ln[c, a:b], index[c, a:b]
        mn, mo, reciprocal = sums_new[c, a:b], sums_old[c, a:b], per_pixel[3, a:b]
        for x in range(n):
            both = (mn[x] + mo[x]) * reciprocal[x] if agree_ab[x] != 0 else hic[x] + loc[x]
            at[x] = inverse_bin(both - lnc[x], first, per_unit, last_bin)
        gather(at, inverse[c], at, n)  # (in place: each lane reads its index before its value is stored)
    n_moving = 0
    if C == 3:  # the three channels of a pixel in one iteration: whole interleaved stores
        v0, v1, v2 = index[0, a:b], index[1, a:b], index[2, a:b]
        row = out[y, a:b]
        for x in range(n):
            keep = moving_ab[x] == 0
            row[x, 0] = row[x, 0] if keep else v0[x]
            row[x, 1] = row[x, 1] if keep else v1[x]
            row[x, 2] = row[x, 2] if keep else v2[x]
    else:
        for c in range(C):
            vc = index[c, a:b]
            for x in range(n):
                out[y, a + x, c] = out[y, a + x, c] if moving_ab[x] == 0 else vc[x]
    for x in range(n):
        n_moving += moving_ab[x] != 0
    return n_moving


@njit(cache=True, nogil=True, error_model="numpy")
def quiet_distances(lin: np.ndarray, dlin: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Per channel of the linearisation (3, levels) float32 and its noise slopes: the largest raw distance d such
    that no pair of raw values at most d apart passes the change test without its share of the local contrast
    (limits as repair_older's), so a rough integer compare rules them out; levels if no pair passes. -1 (none
    known) for tables of more than 256 levels (the search is over all pairs)."""
    C, levels = lin.shape
    out = np.full(C, -1, np.int64)
    if levels > 256:
        return out
    noise_k, floor = limits[1], limits[2]
    for c in range(C):
        best = levels
        for p in range(levels):
            for n in range(levels):
                if abs(lin[c, n] - lin[c, p]) > max(noise_k * (dlin[c, n] + dlin[c, p]), floor):
                    best = min(best, abs(n - p) - 1)
        out[c] = best
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _window_constants(W, radius, floor, out):
    """Per pixel x of a row of W: the floor (linear units) in quantised sums' units over x's window of radius, its
    left half [x - radius, x] and its right half [x, x + radius], each clipped at the row's ends; then the window's
    reciprocal count in linear units per sum. (The statement in numpy: app.decode.motion.window_constants.)"""
    scale = np.float32(MEAN_SCALE)
    for x in range(W):
        first, last = max(x - radius, 0), min(x + radius + 1, W)
        out[0, x] = floor * (scale * np.float32(last - first))
        out[1, x] = floor * (scale * np.float32(x + 1 - first))
        out[2, x] = floor * (scale * np.float32(last - x))
        out[3, x] = np.float32(1.0) / (scale * np.float32(last - first))


@njit(cache=True, nogil=True, error_model="numpy")
def quantised_table(lin: np.ndarray) -> np.ndarray:
    """quantise of every entry of the linearisation (3, levels) float32, as int32: one gather gives a raw value's
    term of the local sums."""
    out = np.empty(lin.shape, np.int32)
    for c in range(lin.shape[0]):
        for v in range(lin.shape[1]):
            out[c, v] = quantise(lin[c, v])
    return out


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def quantise(value: np.float32) -> np.int32:
    """A linear value in int32 steps of 1 / MEAN_SCALE, rounded (negative values to 0), in float32 arithmetic."""
    return np.int32(max(value * np.float32(MEAN_SCALE) + np.float32(0.5), np.float32(0.0)))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _quantise(values, out):
    for x in range(values.shape[0]):
        out[x] = quantise(values[x])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _running_sums(u, v, n, su, sv):
    """su[k] = u[0] + ... + u[k - 1] for k <= n, and the same of v into sv (exact integers; the sums kept in
    registers, not read back from the row)."""
    acc_u = 0
    acc_v = 0
    su[0] = 0
    sv[0] = 0
    for x in range(n):
        acc_u += u[x]
        acc_v += v[x]
        su[x + 1] = acc_u
        sv[x + 1] = acc_v


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _window_sums(sums, s0, a, b, lo_off, hi_off, W, out):
    """out[x - a] = the sum over [x + lo_off, x + hi_off] clipped at the row's ends [0, W), for x in [a, b), from
    running sums that start at pixel s0 (<= every window's first pixel), as float32 (exact). The pixels whose
    window is not clipped through shifted views (a loop that vectorises), the others directly."""
    x0 = min(max(a, -lo_off), b)
    x1 = max(min(b, W - hi_off - 1), x0)
    n = x1 - x0
    top = sums[x0 + hi_off + 1 - s0 : x0 + hi_off + 1 - s0 + n]
    bottom = sums[x0 + lo_off - s0 : x0 + lo_off - s0 + n]
    inner = out[x0 - a : x1 - a]
    for i in range(n):  # (each converted, then subtracted: exact below 2^24, and int32 -> float32 vectorises)
        inner[i] = np.float32(top[i]) - np.float32(bottom[i])
    for x in range(a, x0):
        out[x - a] = np.float32(sums[min(x + hi_off + 1, W) - s0]) - np.float32(sums[max(x + lo_off, 0) - s0])
    for x in range(x1, b):
        out[x - a] = np.float32(sums[min(x + hi_off + 1, W) - s0]) - np.float32(sums[max(x + lo_off, 0) - s0])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _agree_halves(halves, qn, qo, share, floors, mn, mo, agree):
    """From the two frames' local sums over each half of the window (left new, left old, right new, right old) and
    their quantised values qn, qo at the window's centre: the sums over the whole window into mn, mo, and agree[x]
    = 0 where the two frames' sums over the window or either half differ by more than share of their sum plus the
    floor (floors: window, left half, right half)."""
    left_n, left_o, right_n, right_o = halves
    floor_window, floor_left, floor_right = floors
    for x in range(agree.shape[0]):
        u = left_n[x] + right_n[x] - np.float32(qn[x])  # (exact: integers below 2^24)
        v = left_o[x] + right_o[x] - np.float32(qo[x])
        mn[x] = u
        mo[x] = v
        ok = abs(u - v) <= share * (u + v) + floor_window[x]
        ok &= abs(left_n[x] - left_o[x]) <= share * (left_n[x] + left_o[x]) + floor_left[x]
        ok &= abs(right_n[x] - right_o[x]) <= share * (right_n[x] + right_o[x]) + floor_right[x]
        agree[x] = agree[x] if ok else np.float32(0.0)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _is_watched(watched, c):
    for i in range(watched.shape[0]):
        if watched[i] == c:
            return True
    return False


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _envelopes(row, r1, r2, hi1, lo1, hi2, lo2, spans, ends):
    """hi1[x] = max(row[x - r1 : x + r1 + 1]) and lo1[x] = the min, the window clipped at the row's ends, and the
    same over r2 into hi2, lo2. Inside the row from spans doubled to the largest power of two p in each
    window (a sparse table: two reads per pixel), one table for both windows: the wider's spans go on from the
    narrower's. spans: four float32 scratch rows of the row's length, each pass from one pair of rows into the
    other; the pixels whose window the row's ends cut short are done directly. ends: whether row starts and ends
    at the whole row's ends (elsewhere the pixels within a window of them are not used, and left undone)."""
    W = row.shape[0]
    p1 = _span_of(r1)
    p2 = _span_of(r2)
    a_hi, a_lo, b_hi, b_lo = spans
    if p1 == 1:
        _window_from(row, row, r1, p1, hi1, lo1)
    if p2 == 1:
        _window_from(row, row, r2, p2, hi2, lo2)
    s = 1
    state = 0  # the rows holding the spans so far: 0 the row itself, 1 a, 2 b (named rows: the loops vectorise)
    while s < max(p1, p2) and s < W:
        if state == 0:
            _spans_doubled(row, row, s, a_hi, a_lo)
        elif state == 1:
            _spans_doubled(a_hi, a_lo, s, b_hi, b_lo)
        else:
            _spans_doubled(b_hi, b_lo, s, a_hi, a_lo)
        state = 2 if state == 1 else 1
        s *= 2
        for p, radius, hi, lo in ((p1, r1, hi1, lo1), (p2, r2, hi2, lo2)):
            if s == p:
                if state == 1:
                    _window_from(a_hi, a_lo, radius, p, hi, lo)
                else:
                    _window_from(b_hi, b_lo, radius, p, hi, lo)
    for radius, hi, lo in ((r1, hi1, lo1), (r2, hi2, lo2)):
        if ends[0]:  # the pixels whose window the row's ends cut short
            _window_direct(row, radius, hi, lo, range(0, min(radius, W)))
        if ends[1]:
            _window_direct(row, radius, hi, lo, range(max(W - radius, min(radius, W)), W))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _span_of(radius):
    """The largest power of two within a window of 2 radius + 1 pixels."""
    p = 1
    while 2 * p <= 2 * radius + 1:
        p *= 2
    return p


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _spans_doubled(src_hi, src_lo, s, dst_hi, dst_lo):
    """The spans over [x, x + 2 s - 1] from those over [x, x + s - 1], clipped at the row's end. Read through views
    from each offset: an index x + s of unknown sign would get numba's negative-index fix and stay scalar."""
    W = src_hi.shape[0]
    n = W - s
    _max_into(src_hi[:n], src_hi[s:], dst_hi[:n])
    _min_into(src_lo[:n], src_lo[s:], dst_lo[:n])
    _copy_into(src_hi[n:], dst_hi[n:])
    _copy_into(src_lo[n:], dst_lo[n:])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _window_from(span_hi, span_lo, radius, p, hi, lo):
    """The window extremes of the pixels whose whole window lies inside the row, from spans of p pixels: the
    window's first span and its last, which overlap."""
    W = span_hi.shape[0]
    n = W - 2 * radius
    if n > 0:
        shift = 2 * radius - p + 1  # the second span's start, from the window's first pixel
        _max_into(span_hi[:n], span_hi[shift : shift + n], hi[radius : radius + n])
        _min_into(span_lo[:n], span_lo[shift : shift + n], lo[radius : radius + n])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _window_direct(row, radius, hi, lo, pixels):
    """hi[x], lo[x] = the extremes of row over x's window clipped at the row's ends, for x in pixels."""
    W = row.shape[0]
    for x in pixels:
        first = max(x - radius, 0)
        last = min(x + radius, W - 1)
        u = row[first]
        v = row[first]
        for i in range(first + 1, last + 1):
            u = row[i] if row[i] > u else u
            v = row[i] if row[i] < v else v
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
def inverse_bin(value: np.float32, first: np.float32, per_unit: np.float32, last_bin: np.float32) -> np.int32:
    """The bin of the inverse table (motion.inverse_table) nearest to a linear value, for its grid (first bin's
    value, bins per linear unit, last bin's index); values outside are clamped to the first or last bin. Clamped
    in float32, then truncated to int32: the same bin as truncating first (values in (-1, 0) truncate to 0), in
    lanes that vectorise."""
    b = (value - first) * per_unit + np.float32(0.5)
    return np.int32(min(max(b, np.float32(0.0)), last_bin))
