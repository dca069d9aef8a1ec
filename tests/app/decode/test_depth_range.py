"""A depth range that leaves the decoder nothing says so, in one line, instead of blaming the scene."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from app.decode.depth_range import check_depth_range
from app.decode.pipeline import DepthRangeWarning, EmptyResultWarning, FrameSetDecoder
from core.errors import InputError
from core.patterns import make_patterns


@pytest.fixture(scope="module")
def plane(small_rig):
    rig = small_rig("plane", ideal=True, projector_size=(1024, 768))  # four copies across the projector
    ps = make_patterns("two-shot", rig.projector_size)
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    return rig, meta, [rig.render(im) for im in ps.images]


def decode(rig, meta, frames, rng):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = FrameSetDecoder("two-shot", meta, rig.calibration, rng).decode(frames)
    return res, {w.category: str(w.message) for w in caught}


def test_a_range_that_allows_every_copy_says_so(plane):
    rig, meta, frames = plane
    res, said = decode(rig, meta, frames, (100.0, 5000.0))  # the old default: ~6 copies of 256 columns per pixel
    assert not res.stripes.valid.any()
    assert "copies of the stripe sequence" in said[DepthRangeWarning]
    assert "depth range 100-5000 mm" in said[DepthRangeWarning]
    assert "dark" not in said[EmptyResultWarning] and "copies" in said[EmptyResultWarning]


def test_the_working_volume_decodes_to_the_truth_without_a_warning(plane):
    rig, meta, frames = plane
    res, said = decode(rig, meta, frames, rig.depth_range_mm)
    assert not said
    gt = rig.ground_truth
    both = (res.depth > 0) & (gt.depth > 0)
    assert both.sum() > 0.8 * gt.lit.sum()
    err = np.abs(res.depth[both] - gt.depth[both])  # (a 320-px camera sees ~3 projector columns a pixel)
    assert np.median(err) < 0.5 and np.mean(err < 2.0) > 0.99


def test_a_range_behind_the_scene_names_itself_not_only_the_scene(plane):
    rig, meta, frames = plane  # the plane is at 600-900 mm
    res, said = decode(rig, meta, frames, (1500.0, 1800.0))
    assert not res.stripes.valid.any()
    assert DepthRangeWarning not in said
    assert "no surface inside the depth range 1500-1800 mm" in said[EmptyResultWarning]


def test_a_range_no_pixel_sees_a_column_of_is_an_input_error():
    lo = np.full((4, 4), 2000.0, np.float32)  # every pixel's columns beyond a 1024-wide projector
    with pytest.raises(InputError, match=r"^depth range 10-20 mm: no camera pixel sees a projector column"):
        check_depth_range(lo, lo + 50, 1024, 256, (10.0, 20.0))
    assert check_depth_range(lo - 1500, lo - 1400, 1024, 256, (10.0, 20.0)) is None
