"""Two-shot decoder on exactly known synthetic frames: columns, reversed pair, occlusions, reference."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from synth import make_calibration, plane_depth, render

from app.decode import reference
from app.decode.stripemap import StripeMap
from app.decode.twoshot import TwoShotDecoder, TwoShotParams, merge_maps
from app.decode.windows import label
from app.patterns import two_shot_patterns
from app.triangulate import Triangulator


def score(column, truth):
    v = np.isfinite(column)
    err = column - truth.column
    ok = v & truth.lit & (np.abs(np.nan_to_num(err, nan=9)) <= 0.5)
    rmse = float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else float("nan")
    return ok.sum() / max(1, v.sum()), (v & truth.lit).sum() / truth.lit.sum(), rmse


@pytest.fixture(scope="module")
def scene():
    cal = make_calibration()
    ps = two_shot_patterns(cal.projector_size)
    z, ray = plane_depth(cal, 800.0, slope_x=0.3, steps=((200, -80.0),))
    f1, truth = render(cal, ps.images[0], z, ray, seed=1, ambient=0.1)
    f2, _ = render(cal, ps.images[1], z, ray, seed=2, ambient=0.1)
    tri = Triangulator(cal, (500, 1200))
    dec = TwoShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range)
    return cal, ps, f1, f2, truth, tri, dec


def test_columns_match_truth_on_a_tilted_plane_with_a_step(scene):
    _, _, f1, f2, truth, _, dec = scene
    correct, coverage, rmse = score(dec.decode(f1, f2).column, truth)
    assert correct >= 0.995
    assert coverage >= 0.85
    assert rmse <= 0.15


def test_depth_matches_truth(scene):
    _, _, f1, f2, truth, tri, dec = scene
    sm = dec.decode(f1, f2)
    depth = tri.depth(sm.column)
    ok = (depth > 0) & (np.abs(sm.column - truth.column) <= 0.5)
    assert ok.sum() > 0.8 * truth.lit.sum()
    assert np.sqrt(np.mean((depth[ok] - truth.depth[ok]) ** 2)) < 2.0  # 0.15 px x ~14 mm/px at 800 mm


def test_a_pair_out_of_pattern_order_does_not_decode_the_same(scene):
    _, _, f1, f2, _, _, dec = scene
    wrong = dec.decode(f2, f1).column
    assert not np.allclose(np.nan_to_num(wrong), np.nan_to_num(dec.decode(f1, f2).column))


@pytest.mark.parametrize("segmentation", ["events", "runs", "both"])
def test_numba_and_numpy_reference_agree(scene, segmentation):
    cal, ps, f1, f2, _, tri, _ = scene
    sub = (slice(100, 130), slice(None))  # a band of rows keeps the Python reference quick
    small = TwoShotDecoder(
        ps.params,
        cal.projector_size[0],
        column_range=(tri.column_lo[sub], tri.column_hi[sub]),
        params=TwoShotParams(segmentation=segmentation),
    )
    g1, g2 = np.ascontiguousarray(f1[sub]), np.ascontiguousarray(f2[sub])
    a = small.decode(g1, g2)
    b = reference.decode(small, g1, g2)
    np.testing.assert_array_equal(a.valid, b.valid)
    assert a.valid.sum() > 0.8 * a.valid.size
    np.testing.assert_allclose(a.column[a.valid], b.column[b.valid], atol=1e-3)


@pytest.mark.parametrize("segmentation", ["events", "runs"])
def test_pixels_without_a_depth_range_get_no_column_as_in_the_reference(scene, segmentation):
    # rays along which the projector column is not monotone have no range (NaN): a chain crossing them
    # must leave them empty, not extrapolate into them
    cal, ps, f1, f2, _, tri, _ = scene
    sub = (slice(100, 130), slice(None))
    lo, hi = tri.column_lo[sub].copy(), tri.column_hi[sub].copy()
    lo[:, 300:306] = np.nan
    hi[:, 300:306] = np.nan
    small = TwoShotDecoder(
        ps.params, cal.projector_size[0], column_range=(lo, hi), params=TwoShotParams(segmentation=segmentation)
    )
    g1, g2 = np.ascontiguousarray(f1[sub]), np.ascontiguousarray(f2[sub])
    a = small.decode(g1, g2)
    b = reference.decode(small, g1, g2)
    assert not a.valid[:, 300:306].any()
    assert a.valid[:, 280:300].mean() > 0.8 and a.valid[:, 306:326].mean() > 0.8  # the chains go on around them
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_allclose(a.column[a.valid], b.column[b.valid], atol=1e-3)


def test_sixteen_bit_frames_decode_like_eight_bit(scene):
    _, _, f1, f2, truth, _, dec = scene
    a = dec.decode(f1, f2)
    b = dec.decode(f1.astype(np.uint16) * 257, f2.astype(np.uint16) * 257)
    assert (a.valid == b.valid).mean() > 0.99
    correct, _, _ = score(b.column, truth)
    assert correct >= 0.995


def test_all_black_pair_gives_no_value(scene):
    _, _, f1, _, _, _, dec = scene
    black = np.zeros_like(f1)
    assert not dec.decode(black, black).valid.any()


def test_noise_only_gives_no_value(scene):
    _, _, f1, _, _, _, dec = scene
    rng = np.random.default_rng(5)
    a = np.clip(rng.normal(30, 2, f1.shape), 0, 255).astype(np.uint8)
    b = np.clip(rng.normal(30, 2, f1.shape), 0, 255).astype(np.uint8)
    assert dec.decode(a, b).valid.mean() < 0.001


def test_crosstalk_is_unmixed_on_a_blue_surface():
    mixing = np.array([[1.0, 0.1, 0.02], [0.08, 1.0, 0.25], [0.02, 0.09, 1.0]])
    cal = make_calibration(mixing=mixing)
    ps = two_shot_patterns(cal.projector_size)
    z, ray = plane_depth(cal, 800.0)
    albedo = (0.05, 0.08, 0.9)  # G is weak: the B -> G leak is larger than G's own signal
    f1, truth = render(cal, ps.images[0], z, ray, albedo=albedo, seed=3)
    f2, _ = render(cal, ps.images[1], z, ray, albedo=albedo, seed=4)
    tri = Triangulator(cal, (500, 1200))
    plain = TwoShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range)
    unmixed = TwoShotDecoder(ps.params, cal.projector_size[0], mixing, column_range=tri.column_range)
    c_plain, cov_plain, _ = score(plain.decode(f1, f2).column, truth)
    c_unmixed, cov_unmixed, _ = score(unmixed.decode(f1, f2).column, truth)
    assert c_unmixed >= 0.995 and cov_unmixed >= 0.85
    assert cov_plain < 0.5 * cov_unmixed or c_plain < 0.99  # without unmixing the weak channel is wrong


def test_fused_path_equals_the_two_labellings_merged(scene):
    # every segmentation runs fused row by row; it must give exactly what the separate steps give
    cal, ps, f1, f2, _, tri, _ = scene
    dec = TwoShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range)
    dec.params = dataclasses.replace(dec.params, segmentation="both")
    code, feat, thr = dec.classify(f1, f2)
    lp = dec.params.label
    a = label(code, feat, dec.spec, dataclasses.replace(lp, events=True), dec.column_range, thr)
    b = label(code, feat, dec.spec, dataclasses.replace(lp, events=False), dec.column_range, thr)
    fused_runs = dataclasses.replace(dec.params, segmentation="runs")
    merge_maps(a, b)
    fused = dec.decode(f1, f2)
    np.testing.assert_array_equal(fused.column, a.column)
    np.testing.assert_array_equal(fused.confidence, a.confidence)
    assert fused.info["filled"] == a.info["filled"] and fused.info["clashes"] == a.info["clashes"]
    dec.params = fused_runs
    runs = dec.decode(f1, f2)
    np.testing.assert_array_equal(runs.column, b.column)
    assert runs.info == {"chains": b.info["chains"], "chains_dropped": b.info["chains_dropped"]}


def test_a_stripe_map_without_confidence_makes_it_from_its_values():
    """The two-shot decoder leaves the confidence map out (it is 1 where a value, else 0): made when read."""
    col = np.array([[np.nan, 3.5], [7.25, np.nan]], np.float32)
    sm = StripeMap(col, None)
    np.testing.assert_array_equal(sm.confidence, [[0, 1], [1, 0]])
    assert sm.confidence.dtype == np.float32 and sm.confidence is sm.confidence
    sm.confidence = np.full((2, 2), 0.5, np.float32)
    assert float(sm.confidence[0, 0]) == 0.5
