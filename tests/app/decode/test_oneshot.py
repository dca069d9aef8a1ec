"""One-shot decoder against the plain numpy reference (app/decode/reference.py) and the truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from synth import make_calibration, plane_depth, render

from app.decode import reference
from app.decode.oneshot import OneShotDecoder
from app.decode.windows import label
from app.patterns import one_shot_patterns
from app.triangulate import Triangulator


@pytest.fixture(scope="module")
def scene():
    cal = make_calibration()
    ps = one_shot_patterns(cal.projector_size)
    z, ray = plane_depth(cal, 800.0, slope_x=0.3, steps=((200, -80.0),))
    img, truth = render(cal, ps.images[0], z, ray, seed=1, ambient=0.05, albedo=(0.9, 0.7, 0.8))
    tri = Triangulator(cal, (500, 1200))
    return cal, ps, img, truth, tri


@pytest.mark.parametrize("use_hue", [False, True])
def test_classification_matches_the_reference(scene, use_hue):
    cal, ps, img, _truth, tri = scene
    dec = OneShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range)
    dec.params = dataclasses.replace(dec.params, use_hue=use_hue)
    code, feat = dec.classify(img)
    ref_code, ref_feat = reference.classify_one_shot(ps.params, img, gamma=dec.camera_gamma, params=dec.params)
    np.testing.assert_allclose(feat, ref_feat, atol=1e-5)
    assert (code == ref_code).mean() > 0.9999  # float rounding may flip a pixel exactly at the margin
    assert (code >= 0).mean() > 0.5


def test_labelling_matches_the_reference(scene):
    # the same codes through the compiled labelling and the reference's: the same stripes to the pixel
    cal, ps, img, _truth, tri = scene
    band = (slice(100, 130), slice(None))
    lo, hi = (np.ascontiguousarray(a[band]) for a in tri.column_range)
    dec = OneShotDecoder(ps.params, cal.projector_size[0], column_range=(lo, hi))
    code, feat = dec.classify(np.ascontiguousarray(img[band]))
    a = label(code, feat, dec.spec, dec.params.label, (lo, hi))
    pattern, _ = reference.one_shot_pattern(ps.params, cal.projector_size[0])
    b = reference.label_rows(code, feat, None, pattern, dec.params.label, (lo, hi), events=False)
    np.testing.assert_array_equal(a.valid, b.valid)
    assert a.valid.mean() > 0.8
    np.testing.assert_allclose(a.column[a.valid], b.column[b.valid], atol=1e-3)


def test_columns_match_the_truth(scene):
    cal, ps, img, truth, tri = scene
    sm = OneShotDecoder(ps.params, cal.projector_size[0], column_range=tri.column_range).decode(img)
    v = sm.valid
    ok = v & truth.lit & (np.abs(np.nan_to_num(sm.column - truth.column, nan=9)) <= 0.5)
    assert ok.sum() / v.sum() >= 0.99
    assert (v & truth.lit).sum() / truth.lit.sum() >= 0.85
