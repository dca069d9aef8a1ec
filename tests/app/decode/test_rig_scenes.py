"""Decoders against the virtual rig's ground truth (noise, blur, crosstalk, ambient, gamma on)."""

from __future__ import annotations

import numpy as np
import pytest

from app.bench.accuracy import score
from app.decode.graycode import decode_graycode
from app.decode.pipeline import FrameSetDecoder
from app.decode.twoshot import TwoShotDecoder
from app.errors import InputError
from app.patterns import make_patterns


def run(rig, scheme):
    cal = rig.calibration
    cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
    ps = make_patterns(scheme, cal.projector_size)
    meta = {"scheme": scheme, "size": list(ps.size), "images": ps.names, **ps.params}
    frames = [rig.render(im) for im in ps.images]
    res = FrameSetDecoder(scheme, meta, cal, rig.depth_range_mm).decode(frames)
    gt = rig.ground_truth
    return score(res.stripes.column, res.depth, gt.column, gt.depth, gt.lit), res, ps, frames


@pytest.mark.parametrize("scene", ["plane", "steps", "colour_panel"])
def test_two_shot_on_rig_scenes(small_rig, scene):
    (coverage, correct, col_rmse, depth_rmse), _, _, _ = run(small_rig(scene), "two-shot")
    assert correct >= 0.995, f"{scene}: correct {correct:.4f}"
    assert coverage >= (0.85 if scene == "colour_panel" else 0.9), f"{scene}: coverage {coverage:.4f}"
    assert col_rmse <= 0.15
    assert depth_rmse < 1.0


def test_occlusion_steps_give_no_wrong_stripes(small_rig):
    _, res, _, _ = run(small_rig("steps"), "two-shot")
    gt = small_rig("steps").ground_truth
    wrong = res.stripes.valid & ~(np.abs(np.nan_to_num(res.stripes.column - gt.column, nan=9)) <= 0.5)
    assert wrong.sum() <= 0.005 * res.stripes.valid.sum()


def test_one_shot_on_a_neutral_plane(small_rig):
    (coverage, correct, col_rmse, _), _, _, _ = run(small_rig("plane"), "one-shot")
    assert correct >= 0.99 and coverage >= 0.85 and col_rmse <= 0.2


def test_gray_code_columns_and_rows(small_rig):
    rig = small_rig("plane")
    (coverage, correct, col_rmse, _), _, ps, frames = run(rig, "graycode")
    assert correct >= 0.995 and coverage >= 0.98 and col_rmse <= 0.2
    rows = decode_graycode(frames, ps.params, "row")
    gt = rig.ground_truth
    ok = np.isfinite(rows) & gt.lit
    assert ok.sum() >= 0.98 * gt.lit.sum()
    assert np.mean(np.abs(rows[ok] - gt.row[ok]) <= 0.5) >= 0.995


def _two_shot(rig, segmentation=None):
    """A FrameSetDecoder of the rig's calibration and depth range, the rig's two-shot frames, the patterns' params."""
    cal = rig.calibration
    ps = make_patterns("two-shot", cal.projector_size)
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    frames = [rig.render(im) for im in ps.images]
    return FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm, segmentation), frames, ps.params


@pytest.mark.parametrize("segmentation", ["runs", "events", "both"])
def test_two_shot_triangulated_in_the_decoding_pass_is_the_separate_pass(small_rig, segmentation):
    """The two-shot decoder triangulates each row as soon as its columns are final (the triangulator's closed
    form): the same stripe map as decode() and, bit for bit, the depths of Triangulator.depth."""
    fsd, frames, _ = _two_shot(small_rig("colour_panel"), segmentation)
    geometry = fsd.triangulator.moebius_geometry
    assert geometry is not None  # (the virtual rig's projector is nearly a Moebius map)
    sm, depth = fsd.decoder.decode_depth(frames[0], frames[1], geometry)
    alone = fsd.decoder.decode(frames[0], frames[1])
    np.testing.assert_array_equal(sm.column, alone.column)
    assert sm.chain is None and alone.chain is None  # (the fused path keeps only its last two rows of chains)
    want = fsd.triangulator.depth(alone.column)
    assert (want > 0).mean() > 0.5
    np.testing.assert_array_equal(depth, want)
    assert np.array_equal(fsd.stripes_and_depth(frames)[1], want)


def test_two_shot_depth_pass_refuses_geometry_of_another_size(small_rig):
    fsd, frames, _ = _two_shot(small_rig("plane"))
    planes, w0, w_span = fsd.triangulator.moebius_geometry
    with pytest.raises(InputError, match="calibration camera is"):
        fsd.decoder.decode_depth(frames[0][:-8], frames[1][:-8], (planes, w0, w_span))


def test_two_shot_takes_a_float64_column_range(small_rig):
    """The column range is read by the row kernel as float32 C arrays: a float64 or Fortran-ordered range (what
    a caller may build with numpy) is converted, not a compile error."""
    fsd, frames, params = _two_shot(small_rig("plane"))
    lo, hi = fsd.triangulator.column_range
    want = fsd.decoder.decode(frames[0], frames[1]).column
    cal = fsd.calibration
    ranges = (lo.astype(np.float64), np.asfortranarray(hi))
    dec = TwoShotDecoder(params, cal.projector_size[0], cal.color_mixing, ranges, camera_gamma=fsd.decoder.camera_gamma)
    np.testing.assert_array_equal(dec.decode(frames[0], frames[1]).column, want)
