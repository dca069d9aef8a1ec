"""Vectorised kernel paths (gathers of app/decode/simd.py, fast paths) against the loops they replace, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from synth import make_calibration, plane_depth, render

from app.decode import fast
from app.decode.fast import chains, classify, columns, differences, lookup, rows, runs
from app.decode.fast.bundles import (
    NO_LACKING,
    NO_LEAK,
    ChainMap,
    Classifier,
    FrameTables,
    LabelSettings,
    Runs,
    StripeCode,
)
from app.decode.fast.lacking_edges import NO_LACKING_EDGES
from app.decode.primitives import append_sparse, append_where, fill_eight, run_bounds
from app.decode.response_inverse import identity_inverse
from app.decode.simd import gather8, spread8x2
from app.decode.twoshot import TwoShotDecoder, two_shot_spec
from app.patterns import two_shot_patterns

UNPACKED = np.empty(0, np.int64)  # no packed tables: the two-gather path


@njit(cache=False)
def _dispatched(f1, f2, lin, dlin, unmix, ta, out, pk=UNPACKED):
    for y in range(f1.shape[0]):
        ahead = ((lin, 0),)  # rows the pair path prefetches (a hint only: any row)
        differences.differences(f1, f2, y, lin, dlin, pk, unmix, ta, out[y], ahead)


def _packed(lin, dlin):
    """The (lin, dlin) pairs as int64 entries, by numpy (what pack_tables builds, for any number of levels)."""
    return np.stack([lin, dlin], axis=-1).reshape(-1).view(np.int64)


@njit(cache=False)
def _scalar(f1, f2, lin, dlin, u, ta, out):
    for y in range(f1.shape[0]):
        o = out[y]
        differences._row_differences(
            f1[y], f2[y], (lin[0], lin[1], lin[2]), (dlin[0], dlin[1], dlin[2]),
            (u[0, 0], u[0, 1], u[0, 2], u[1, 0], u[1, 1], u[1, 2], ta), (o[0], o[1], o[2], o[3]),
        )  # fmt: skip


@pytest.mark.parametrize("tables", ["plain", "packed", "pairs", "shared pairs"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("width", [5, 16, 17, 47, 640])
def test_gathered_differences_equal_the_scalar_loop(dtype, width, tables):
    rng = np.random.default_rng(width)
    levels = np.iinfo(dtype).max + 1
    f1 = rng.integers(0, levels, (3, width, 3)).astype(dtype)
    f2 = rng.integers(0, levels, (3, width, 3)).astype(dtype)
    f1[0, :4] = 0  # both ends of the tables
    f2[0, :4] = levels - 1
    lin = (255 * rng.random((3, levels))).astype(np.float32)
    dlin = rng.random((3, levels)).astype(np.float32)
    if tables == "shared pairs":  # the three channels' tables equal: one pair table for all
        lin[1:] = lin[0]
        dlin[1:] = dlin[0]
    unmix = rng.normal(size=(2, 3)).astype(np.float32)
    ta = np.float32(1.0)
    got = np.full((3, 6, width), np.nan, np.float32)
    want = np.full((3, 6, width), np.nan, np.float32)
    pk = {"plain": UNPACKED, "packed": _packed(lin, dlin)}.get(tables)
    if pk is None:  # (16-bit tables have no pair table: the plain gathers)
        pk = fast.pair_tables(lin, dlin)
        assert pk.size == (0 if dtype == np.uint16 else (1 if tables == "shared pairs" else 3) * 65536)
    _dispatched(f1, f2, lin, dlin, unmix, ta, got, pk)
    _scalar(f1, f2, lin, dlin, unmix, ta, want)
    np.testing.assert_array_equal(got[:, :4], want[:, :4])
    assert np.isnan(got[:, 4:]).all()  # rows past the fourth are left alone


def test_pair_table_entries_are_the_differences_and_noise_sums_of_value_pairs():
    rng = np.random.default_rng(3)
    lin = (255 * rng.random((3, 256))).astype(np.float32)
    dlin = rng.random((3, 256)).astype(np.float32)
    pairs = fast.pair_tables(lin, dlin).view(np.float32).reshape(3, 256, 256, 2)
    np.testing.assert_array_equal(pairs[..., 0], lin[:, None, :] - lin[:, :, None])  # [c, a, b] = lin[b] - lin[a]
    np.testing.assert_array_equal(pairs[..., 1], dlin[:, None, :] + dlin[:, :, None])


def test_frames_that_are_views_decode_as_their_copies():
    """Non-contiguous frames (a crop of wider ones) give the contiguous frames' result (the decoder copies them:
    the kernels are compiled for C-contiguous frames only)."""
    cal = make_calibration()
    ps = two_shot_patterns(cal.projector_size)
    z, ray = plane_depth(cal, 800.0, slope_x=0.3)
    f1, _ = render(cal, ps.images[0], z, ray, seed=1, ambient=0.1)
    f2, _ = render(cal, ps.images[1], z, ray, seed=2, ambient=0.1)
    dec = TwoShotDecoder(ps.params, cal.projector_size[0])
    pad1 = np.zeros((f1.shape[0], f1.shape[1] + 3, 3), f1.dtype)
    pad2 = np.zeros_like(pad1)
    pad1[:, 3:] = f1
    pad2[:, 3:] = f2
    view1, view2 = pad1[:, 3:], pad2[:, 3:]
    assert not view1.flags.c_contiguous
    a = dec.decode(f1, f2)
    b = dec.decode(view1, view2)
    assert np.isfinite(a.column).mean() > 0.5
    np.testing.assert_array_equal(a.column, b.column)


@njit(cache=False)
def _gather_all(dst, table, idx):
    i = 0
    while i + 8 <= idx.shape[0]:
        gather8(dst, table, idx, i)
        i += 8
    return i


@pytest.mark.parametrize(
    "value, out",
    [
        (np.float32, np.float32),
        (np.float64, np.float64),
        (np.int32, np.int32),
        (np.int64, np.int64),
        (np.float32, np.float64),  # widened
        (np.int32, np.int64),
    ],
)
@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_gather8_reads_the_table_at_each_index(value, out, index):
    rng = np.random.default_rng(3)
    table = ((rng.random(1000) - 0.5) * 1e6).astype(value)
    idx = rng.integers(0, 1000, 40).astype(index)
    idx[:2] = (0, 999)
    dst = np.zeros(41, out)
    assert _gather_all(dst, table, idx) == 40
    np.testing.assert_array_equal(dst[:40], table[idx].astype(out))
    assert dst[40] == 0  # nothing written past the last group of eight


@njit(cache=False)
def _runs(code, fr, wts, link_ok, gap_max):
    n = 3 * (2 * code.shape[0] + 8)
    rs = np.zeros(n, np.int64)
    re = np.zeros(n, np.int64)
    rc = np.zeros(n, np.int64)
    link = np.zeros(n, np.bool_)
    edge = np.zeros(n, np.float64)
    trans = runs.transitions(wts, link_ok, n)
    nr = runs.pixel_runs(code, fr, wts, trans, gap_max, Runs(rs, re, rc, link, edge, np.zeros(n, np.int64)))
    return rs[:nr], re[:nr], rc[:nr], link[:nr], edge[:nr]


def test_gathered_link_pass_equals_the_loop():
    """The runs, links and edges of a row from C-contiguous differences (gathered link pass) and from a strided
    view of the same values (the loop), on codes with gaps, unknown pixels and unlinkable transitions."""
    ws = two_shot_spec(two_shot_patterns((1024, 768)).params, 1024)
    rng = np.random.default_rng(5)
    W = 997
    code = np.repeat(rng.integers(-1, 4, W), rng.integers(1, 4, W))[:W].astype(np.int8)
    fr = rng.normal(size=(2, W)).astype(np.float32)
    strided = np.zeros((2, 2 * W), np.float32)[:, ::2]  # same values, not C-contiguous
    strided[:] = fr
    assert fr.flags.c_contiguous and not strided.flags.c_contiguous
    got = _runs(code, fr, ws.weights, ws.link_ok, 1)
    want = _runs(code, strided, ws.weights, ws.link_ok, 1)
    assert len(got[0]) > 300 and got[3].sum() > 100
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)


IDENTITY_8BIT = identity_inverse(np.uint8)  # (no raw mosaic here: the inverse is not read)


@njit(cache=False)
def _fused_codes(f1, f2, lin, dlin, pk, unmix, t_abs, t_rel, block, code):
    scratch = classify.classify_scratch(unmix.shape[0], f1.shape[1], block)
    tables = FrameTables(lin, dlin, pk, IDENTITY_8BIT)
    classifier = Classifier(unmix, t_abs, t_rel, t_rel, block, NO_LACKING, NO_LEAK)
    for y in range(f1.shape[0]):
        ahead = ((scratch.block_max, 0),)  # (a row to prefetch: any)
        classify.classify_row(f1, f2, y, tables, classifier, scratch, False, ahead)
        code[y] = scratch.code


@pytest.mark.parametrize("tables", ["packed", "pairs"])
@pytest.mark.parametrize("channels", [2, 3])  # 3: _classify_row_any, the path for other channel counts
@pytest.mark.parametrize("width", [64, 61])
def test_row_classification_skips_nan_like_the_specification(width, channels, tables):
    """A camera response with NaN entries (a bad calibration) makes some differences NaN: the row kernel's
    block maxima skip them and give them no sign, as twoshot_classify (the specification) does."""
    rng = np.random.default_rng(7)
    f1 = rng.integers(0, 256, (6, width, 3)).astype(np.uint8)
    f2 = rng.integers(0, 256, (6, width, 3)).astype(np.uint8)
    f1[:, ::8, 1] = 17  # the first pixel of every block reads the NaN entry
    lin = np.tile(np.linspace(0, 255, 256, dtype=np.float32), (3, 1))
    lin[1, 17] = np.nan
    dlin = np.ones((3, 256), np.float32)
    unmix = np.array([[0.1, 1.0, 0.05], [0.0, 0.1, 1.0], [1.0, 0.05, 0.0]][:channels], np.float32)
    want = np.empty((6, width), np.int8)
    feat = np.empty((6, width, channels), np.float32)
    noise = np.empty((6, width, channels), np.float32)
    args = (np.float32(2.0), np.float32(0.03))
    fast.twoshot_classify(f1, f2, lin, dlin, unmix, *args, np.float32(0.03), 8, want, feat, noise)
    got = np.empty((6, width), np.int8)
    pk = fast.pair_tables(lin, dlin) if tables == "pairs" else fast.pack_tables(lin, dlin)
    assert pk.size == (3 * 65536 if tables == "pairs" else 3 * 256)  # (the NaN makes the channels' tables differ)
    _fused_codes(f1, f2, lin, dlin, pk, unmix, *args, 8, got)
    assert np.isnan(feat[:, ::8, 0]).all() and (want >= 0).mean() > 0.3
    np.testing.assert_array_equal(got, want)


def test_differences_fall_back_to_the_loop_for_what_the_gathers_do_not_take():
    """RGBA frames (4 channels: the gathers read 3 per pixel) and float64 coefficients take the loop, with the
    loop's result, instead of a wrong result or a compile error."""
    rng = np.random.default_rng(11)
    f1 = rng.integers(0, 256, (2, 40, 4)).astype(np.uint8)
    f2 = rng.integers(0, 256, (2, 40, 4)).astype(np.uint8)
    lin = (255 * rng.random((3, 256))).astype(np.float32)
    dlin = rng.random((3, 256)).astype(np.float32)
    unmix = rng.normal(size=(2, 3)).astype(np.float32)
    want = np.zeros((2, 6, 40), np.float32)
    _scalar(f1, f2, lin, dlin, unmix, np.float32(1.0), want)
    got = np.zeros((2, 6, 40), np.float32)
    _dispatched(f1, f2, lin, dlin, unmix, np.float32(1.0), got)
    np.testing.assert_array_equal(got, want)
    got64 = np.zeros((2, 6, 40), np.float64)
    _dispatched(f1[..., :3].copy(), f2[..., :3].copy(), lin, dlin, unmix.astype(np.float64), 1.0, got64)
    assert np.isfinite(got64[:, :4]).all()


def _increasing_loop(src):
    out = src.copy()
    for r in range(1, len(out)):
        out[r] = out[r - 1] + 1e-3 if src[r] <= out[r - 1] else src[r]
    return out


@pytest.mark.parametrize(
    "values",
    [[1.0, 2.0, 3.5], [1.0, 1.0, 0.5, 4.0], [3.0, 2.0, 1.0], [1.0, np.nan, 2.0], [5.0], []],
)
def test_nodes_made_increasing_as_the_sequential_loop_does(values):
    src = np.array(values, np.float64)
    x = np.append(src, -7.0)
    chains.increasing(x, len(src))
    np.testing.assert_array_equal(x[: len(src)], _increasing_loop(src))
    assert x[len(src)] == -7.0


@njit(cache=False)
def _run_bounds(code, rs, re, rc):
    return run_bounds(code, rs, re, rc)


def _runs_by_hand(code):
    runs, x = [], 0
    while x < len(code):
        x1 = x
        while x1 + 1 < len(code) and code[x1 + 1] == code[x]:
            x1 += 1
        if code[x] >= 0:
            runs.append((x, x1, int(code[x])))
        x = x1 + 1
    return runs


@pytest.mark.parametrize("width", [1, 2, 17, 18, 19, 34, 35, 640, 641])
def test_compressed_run_bounds_equal_the_runs_by_hand(width):
    rng = np.random.default_rng(width)
    for trial in range(40):
        # runs of 1-3 pixels of codes 0..3 and no code (-1), like a two-shot row; the first trials all one code
        code = np.repeat(rng.integers(-1, 4, width), rng.integers(1, 4, width))[:width].astype(np.int8)
        if trial < 2:
            code[:] = trial - 1
        expected = _runs_by_hand(code)
        for row in (code, np.repeat(code, 2)[::2]):  # C-contiguous (compressed stores) and strided (the loop)
            for dtype in (np.int32, np.int64):  # (int32: the decoder's, sixteen to a register)
                rs, re, rc = (np.full(2 * width + 16, -7, dtype) for _ in range(3))
                n = _run_bounds(row, rs, re, rc)
                assert list(zip(rs[:n].tolist(), re[:n].tolist(), rc[:n].tolist(), strict=True)) == expected
                assert (rs[n + 16 :] == -7).all() and (re[n + 16 :] == -7).all()  # (whole vectors, nothing beyond)


def _labels_by_windows(pos, k, period):
    """The confirmed labels window by window (the loop _confirmed_labels replaces for k = 7)."""
    nr = len(pos)
    lab = [-1] * nr
    for j, p in enumerate(pos):
        if p < 0:
            continue
        after_prev = j > 0 and pos[j - 1] >= 0 and p == (pos[j - 1] + 1) % period
        before_next = j + 1 < nr and pos[j + 1] >= 0 and pos[j + 1] == (p + 1) % period
        if not (after_prev or before_next):
            continue
        for t in range(k):
            lv = (p + t) % period
            lab[j + t] = lv if lab[j + t] in (-1, lv) else -2
    return lab


@pytest.mark.parametrize("period", [16, 13, 7])
@pytest.mark.parametrize("nr", [1, 2, 3, 7, 8, 40, 300])
def test_vectorised_confirmed_labels_equal_the_window_loop(nr, period):
    rng = np.random.default_rng(nr)
    k = 7
    for trial in range(60):
        # continuing stretches (with wrap-around), isolated windows, gaps and clashing stretches
        steps = np.where(rng.random(nr) < 0.8, 1, rng.integers(0, period, nr))
        pos = np.cumsum(steps) if trial % 3 else rng.integers(-1, 4, nr)
        pos = np.where(rng.random(nr) < 0.1, -1, pos % period).astype(np.int64)
        pos[max(nr - k + 1, 0) :] = -1  # no window starts in the last k - 1 runs
        lab = np.full(nr, -9, np.int32)
        lookup.confirmed_labels(nr, pos, lab, k, period, np.empty(nr + k, np.int32))
        assert lab.tolist() == _labels_by_windows(pos.tolist(), k, period)


@njit(cache=False)
def _append_where(flags, n, out):
    return append_where(flags, n, out)


@njit(cache=False)
def _append_sparse(flags, n, out):
    return append_sparse(flags, n, out)


@pytest.mark.parametrize("density", [0.3, 0.01])  # (0.01: mostly blocks of 16 without a flag, which sparse skips)
@pytest.mark.parametrize("append", [_append_where, _append_sparse])
@pytest.mark.parametrize("n", [0, 1, 15, 16, 17, 33, 300])
def test_compressed_positions_equal_flatnonzero(n, append, density):
    rng = np.random.default_rng(n)
    flags = rng.random(n + 5) < density
    expected = np.flatnonzero(flags[:n]).tolist()
    for f in (flags, flags.astype(np.int8) * 3, np.repeat(flags, 2)[::2]):  # bool, int8, strided (the loop)
        for dtype in (np.int32, np.int64):
            out = np.full(n + 32, -7, dtype)
            m = append(f, n, out)
            assert out[:m].tolist() == expected
            assert (out[m + 16 :] == -7).all()  # (whole vectors: at most 16 entries past the last written)


@pytest.mark.parametrize("spacing", [0.4, 2.2, 4.5, 7.9, 12.0])  # node spacings in pixels: short and long segments
def test_pixel_segments_are_after_the_last_interior_node_left_of_each_pixel(spacing):
    rng = np.random.default_rng(int(10 * spacing))
    for trial in range(30):
        nn = int(rng.integers(1, 40))
        nx = np.sort(rng.uniform(-3, spacing * nn, nn)) + np.arange(nn) * 1e-6  # increasing
        if trial % 5 == 0:
            nx[nn // 2 :] += 20  # one long segment amid short ones
        vals = 100 + 3 * np.arange(nn, dtype=np.int64)
        xa, xb = int(np.floor(nx[0])) + int(rng.integers(-1, 2)), int(np.ceil(nx[-1])) + int(rng.integers(-1, 2))
        nxp = max(xb - xa + 1, 1)
        out = np.full(nxp + 16, -7, np.int64)
        seg_of = np.empty(nxp + 16, np.int64)
        columns.segment_values(nx, nn, xa, nxp, np.empty(nn + 1, np.int64), seg_of, vals, out)
        pixels = xa + np.arange(nxp)
        expected = [max([r for r in range(1, nn - 1) if np.floor(nx[r]) + 1 <= x] or [0]) for x in pixels]
        assert out[:nxp].tolist() == vals[expected].tolist()
        assert (out[nxp + 8 :] == -7).all()  # nothing past the room the caller keeps


@njit(cache=False)
def _fill8(arr, i, value):
    fill_eight(arr, i, value)


@pytest.mark.parametrize("dtype", [np.int64, np.float32])
def test_fill8_writes_eight_values_and_nothing_else(dtype):
    for arr in (np.zeros(20, dtype), np.zeros(40, dtype)[::2]):  # one vector store; strided: the loop
        _fill8(arr, 5, dtype(3))
        assert arr.tolist() == [0] * 5 + [3] * 8 + [0] * 7


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_pair_texture_is_the_floor_average_without_overflow(dtype):
    from app.decode.pipeline import average_frames_of

    rng = np.random.default_rng(7)
    top = np.iinfo(dtype).max
    a, b = (rng.integers(0, top + 1, (5, 7, 3)).astype(dtype) for _ in range(2))
    a[0, 0], b[0, 0] = top, top  # the sum overflows the dtype
    expected = ((a.astype(np.uint32) + b) // 2).astype(dtype)
    assert np.array_equal(average_frames_of(a, b), expected)  # compiled pass
    assert np.array_equal(average_frames_of(a[:, ::-1], b[:, ::-1]), expected[:, ::-1])  # views: numpy


@pytest.mark.parametrize("edges_mode", [False, True])
def test_vote_counts_written_with_the_columns_equal_counts_of_the_finished_rows(edges_mode):
    """Two chains whose end runs share a pixel (a zero crossing exactly on a pixel): the later chain owns it,
    and the counts made while writing must say so, as counting the finished rows does."""
    W, k, A, period, sw, nr, cap = 60, 7, 4, 64, 8.0, 16, 10
    n = 3 * (2 * W + 8)
    row_runs, scratch = rows.row_scratch(n, W, 1)
    rs, re, rc, link, edge, _ = row_runs
    codes = np.random.default_rng(0).integers(0, A, nr)
    for i in range(nr):  # runs of 4 pixels, each sharing its last pixel with the next run
        rs[i], re[i], rc[i], link[i], edge[i] = 3 * i + 1, 3 * i + 4, codes[i], i + 1 < nr, 3 * i + 4.0
    table = np.full(A**k, -1, np.int32)
    for j, p in ((0, 10), (1, 11), (8, 40), (9, 41)):  # chain A: runs 0-7, chain B: runs 8-15
        table[sum(int(codes[j + t]) << (2 * t) for t in range(k))] = p
    col = np.full((2, W), np.nan, np.float32)
    chain = np.full((2, W), -1, np.int32)
    agree, disagree, npx = (np.zeros(cap, np.int32) for _ in range(3))
    span = np.zeros((cap, 2), np.int32)
    out = ChainMap(col, chain, agree, disagree, npx, span, np.zeros(3, np.int64))
    lo = np.zeros((2, W), np.float32)
    stripes = StripeCode(table, np.ones((A, A), np.bool_), np.zeros((A, A, 2), np.float32))
    settings = LabelSettings(k, period, sw, 1, 1000, 2, 0.5, 0, 1.0, 0.3, edges_mode, False, NO_LACKING_EDGES)
    nc = 0
    for y in range(2):  # row 1 is row 0 again: every pixel pair agrees
        nc = rows.label_row(y, nr, row_runs, scratch, stripes, settings, lo, lo, out, nc)
    assert nc == 4 and span[0, 1] == span[1, 0]  # the shared pixel
    for c in range(nc):
        y = c // 2
        mine = chain[y] == c
        assert npx[c] == mine.sum()
        if y == 1:  # votes against row 0, by the row's final owners
            pair = mine & (chain[0] >= 0)
            assert agree[c] == (pair & (np.abs(col[0] - col[1]) <= 1.0)).sum() and disagree[c] == 0


@pytest.mark.parametrize("levels", [256, 65536])  # 8- and 16-bit frames
def test_tables_are_packed_in_pairs(levels):
    rng = np.random.default_rng(3)
    lin, dlin = rng.random((2, 3, levels)).astype(np.float32)
    assert np.array_equal(fast.pack_tables(lin, dlin), _packed(lin, dlin))
    assert fast.pack_tables(lin, dlin[:2]).size == 0  # tables of different shapes: none


@njit(cache=False)
def _spread(src, dst, n):
    for i in range(n):
        spread8x2(src, 2 * i, dst, 16 * i)


def test_spread8x2_writes_two_values_over_eight_lanes_each_and_nothing_else():
    src = np.arange(1, 9, dtype=np.float32) * 1.5
    dst = np.full(56, -1.0, np.float32)
    _spread(src, dst, 3)
    np.testing.assert_array_equal(dst[:48], np.repeat(src[:6], 8))
    assert (dst[48:] == -1.0).all()


AVX2_PROBE = """
import numpy as np
from numba import njit
from app.decode.primitives import append_where
from app.decode.simd import compress_by_permute

@njit
def positions(flags, n, out):
    return append_where(flags, n, out)

out = np.zeros(64, np.int32)
positions(np.ones(40, np.bool_), 40, out)
asm = next(iter(positions.inspect_asm().values()))
print(compress_by_permute(), "vpermd" in asm, "zmm" in asm)
"""


def test_an_avx2_build_appends_by_permutes_and_gathers_lane_by_lane_with_the_same_results(tmp_path):
    """The permuted appends and the lane-by-lane loads (simd._masked_gather without AVX-512) run only in an AVX2
    build: this file's append and gather tests, compiled for Haswell."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from app.bench.speed import AVX2_ENV

    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(AVX2_ENV, NUMBA_CACHE_DIR=str(tmp_path))
    probe = subprocess.run([sys.executable, "-c", AVX2_PROBE], env=env, capture_output=True, text=True)
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.split() == ["True", "True", "False"]  # permutes, no 512-bit registers
    here = Path(__file__)
    chosen = "compressed or (gather and not avx2)"
    tests = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(here), "-k", chosen],
        env=env, cwd=here.parents[3], capture_output=True, text=True,
    )  # fmt: skip
    assert tests.returncode == 0, tests.stdout[-2000:]
    assert " passed" in tests.stdout and " failed" not in tests.stdout
