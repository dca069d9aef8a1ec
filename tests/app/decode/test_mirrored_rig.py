"""A projector mounted upside down: its columns run right to left in the camera, and both colour
decoders still identify every window (they read the mirrored image; app/decode/mirror.py)."""

from __future__ import annotations

import numpy as np
import pytest
from synth import make_calibration, plane_depth, render

from app.decode.mirror import columns_run_backwards
from app.decode.oneshot import OneShotDecoder
from app.decode.pipeline import FrameSetDecoder
from app.decode.twoshot import TwoShotDecoder
from app.patterns import one_shot_patterns, two_shot_patterns
from app.triangulate import Triangulator


def score(column, truth):
    v = np.isfinite(column)
    ok = v & truth.lit & (np.abs(np.nan_to_num(column - truth.column, nan=9)) <= 0.5)
    return ok.sum() / max(1, v.sum()), (v & truth.lit).sum() / truth.lit.sum()


@pytest.fixture(scope="module")
def rig():
    cal = make_calibration(roll_deg=180.0)
    z, ray = plane_depth(cal, 800.0, slope_x=0.3)
    tri = Triangulator(cal, (500, 1200))
    return cal, z, ray, tri


def test_the_calibration_says_columns_run_backwards(rig):
    tri = rig[3]
    assert columns_run_backwards(tri.column_range)
    upright = Triangulator(make_calibration(), (500, 1200))
    assert not columns_run_backwards(upright.column_range)
    assert not columns_run_backwards(None)


def test_two_shot_decodes_an_upside_down_projector(rig):
    cal, z, ray, tri = rig
    ps = two_shot_patterns(cal.projector_size)
    f1, truth = render(cal, ps.images[0], z, ray, seed=1, ambient=0.1)
    f2, _ = render(cal, ps.images[1], z, ray, seed=2, ambient=0.1)
    assert np.nanmean(np.diff(truth.column, axis=1)) < 0  # the scene really is mirrored
    dec = TwoShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range)
    assert dec.mirrored
    sm = dec.decode(f1, f2)
    correct, coverage = score(sm.column, truth)
    assert correct >= 0.995 and coverage >= 0.9
    depth = tri.depth(sm.column)
    good = (depth > 0) & truth.lit
    assert np.median(np.abs(depth[good] - z[good])) < 0.5
    # read left to right, every window is some other window of the maximal sequence: consistently wrong
    # columns that no vertical check can catch (only the depth range masks some)
    dec.mirrored, dec.column_range = False, tri.column_range
    wrong = dec.decode(f1, f2)
    assert wrong.valid.mean() > 0.1 and score(wrong.column, truth)[0] < 0.2


def test_one_shot_decodes_an_upside_down_projector(rig):
    cal, z, ray, tri = rig
    ps = one_shot_patterns(cal.projector_size)
    img, truth = render(cal, ps.images[0], z, ray, seed=3, ambient=0.05)
    dec = OneShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range)
    assert dec.mirrored
    correct, coverage = score(dec.decode(img).column, truth)
    assert correct >= 0.99 and coverage >= 0.85


def test_a_mirrored_two_shot_rig_is_triangulated_apart(rig):
    """decode_depth decodes a mirrored rig's mirrored image, so it leaves the depth map to the caller (None)."""
    cal, z, ray, tri = rig
    ps = two_shot_patterns(cal.projector_size)
    f1, _ = render(cal, ps.images[0], z, ray, seed=1, ambient=0.1)
    f2, _ = render(cal, ps.images[1], z, ray, seed=2, ambient=0.1)
    dec = TwoShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range)
    geometry = tri.moebius_geometry
    assert geometry is not None
    sm, depth = dec.decode_depth(f1, f2, geometry)
    assert depth is None
    np.testing.assert_array_equal(sm.column, dec.decode(f1, f2).column)


def test_a_mirrored_two_shot_rig_gets_the_separate_passs_depth(rig):
    """FrameSetDecoder.stripes_and_depth on a mirrored rig: the depth map of Triangulator.depth."""
    cal, z, ray, _ = rig
    ps = two_shot_patterns(cal.projector_size)
    f1, _ = render(cal, ps.images[0], z, ray, seed=1, ambient=0.1)
    f2, _ = render(cal, ps.images[1], z, ray, seed=2, ambient=0.1)
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    fsd = FrameSetDecoder("two-shot", meta, cal, (500, 1200))
    assert fsd.decoder.mirrored and fsd.triangulator.moebius_geometry is not None
    sm, depth = fsd.stripes_and_depth([f1, f2])
    assert (depth > 0).mean() > 0.5
    np.testing.assert_array_equal(depth, fsd.triangulator.depth(sm.column))
