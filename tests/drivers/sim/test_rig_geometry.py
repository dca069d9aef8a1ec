"""The virtual rig's geometry against the true calibration, checked with OpenCV's own functions."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from core.patterns import graycode_patterns, two_shot_patterns
from drivers.sim.rig import VirtualRig

CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


@pytest.fixture(scope="module", params=["plane_tilted", "objects", "face"])
def rig(request) -> VirtualRig:
    return VirtualRig.from_preset(request.param, camera_size=(320, 240))


def test_ground_truth_column_and_row_agree_with_cv2_projection(rig: VirtualRig) -> None:
    cal = rig.calibration
    gt = rig.ground_truth
    lit = gt.lit
    assert lit.mean() > 0.5
    X = gt.points[lit].astype(np.float64)
    rvec, _ = cv2.Rodrigues(cal.R)
    uv, _ = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, cal.T, cal.projector_matrix, cal.projector_distortion)
    uv = uv.reshape(-1, 2)
    assert np.abs(uv[:, 0] - gt.column[lit]).max() < 0.05
    assert np.abs(uv[:, 1] - gt.row[lit]).max() < 0.05
    # the points lie on the rays of their own camera pixels, and depth is their Z
    ys, xs = np.nonzero(lit)
    cam, _ = cv2.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cal.camera_matrix, cal.camera_distortion)
    cam = cam.reshape(-1, 2)
    assert np.abs(cam[:, 0] - xs).max() < 0.01 and np.abs(cam[:, 1] - ys).max() < 0.01
    assert np.allclose(gt.depth[lit], X[:, 2], atol=1e-3)
    # unlit pixels carry NaN, no-surface pixels depth 0
    assert np.all(np.isnan(gt.column[~lit])) and np.all(np.isnan(gt.row[~lit]))
    assert np.all(gt.depth[~gt.visible] == 0)
    near, far = rig.depth_range_mm
    assert near <= gt.depth[gt.visible].min() and gt.depth.max() <= far


def test_single_projector_column_lands_where_the_calibration_predicts() -> None:
    rig = VirtualRig.from_preset("plane", ideal=True)
    cal = rig.calibration
    wp, hp = rig.projector_size
    col = 517
    pattern = np.zeros((hp, wp, 3), np.uint8)
    pattern[:, col] = 255
    img = rig.render(pattern)
    lit = img[..., 1] > 0
    assert lit.any(axis=1).all(), "the column crosses every camera row"
    # independent prediction: camera pixel -> ray -> the plane Z = 720 mm -> projector column
    h, w = lit.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(pts, cal.camera_matrix, cal.camera_distortion, R=np.eye(3), P=np.eye(3), criteria=CRIT)
    X = np.concatenate([xy.reshape(-1, 2), np.ones((xy.shape[0], 1))], axis=1) * 720.0
    rvec, _ = cv2.Rodrigues(cal.R)
    uvp, _ = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, cal.T, cal.projector_matrix, cal.projector_distortion)
    pred = uvp.reshape(h, w, 2)[..., 0]
    assert np.all(np.abs(pred[lit] - col) <= 0.5 + 1e-6)  # every lit pixel sees that column
    assert np.all(lit[np.abs(pred - col) < 0.499])  # and every pixel that sees it is lit
    # ~2 camera pixels per projector pixel in the middle of the working range (as in the paper)
    assert 1.6 < lit.sum(axis=1).mean() < 2.6


@pytest.mark.parametrize("bits", [8, 16])
def test_ideal_white_plane_reproduces_the_pattern_exactly(bits: int) -> None:
    rig = VirtualRig.from_preset("plane", ideal=True, bit_depth=bits)
    gt = rig.ground_truth
    assert gt.lit.all()
    c, r = gt.column.astype(np.float64), gt.row.astype(np.float64)
    # stay off the rounding boundary between two projector pixels (float32 ground truth)
    safe = (np.abs((c % 1) - 0.5) > 1e-3) & (np.abs((r % 1) - 0.5) > 1e-3)
    ci, ri = np.floor(c + 0.5).astype(int), np.floor(r + 0.5).astype(int)
    scale = 257 if bits == 16 else 1
    pats = two_shot_patterns(rig.projector_size).images + graycode_patterns(rig.projector_size).images[2:6]
    levels = np.random.default_rng(3).integers(0, 256, (*rig.projector_size[::-1], 3), dtype=np.uint8)
    for pat in [*pats, levels]:
        img = rig.render(pat)
        assert img.dtype == (np.uint16 if bits == 16 else np.uint8)
        expected = pat[ri, ci].astype(np.int64) * scale
        assert np.array_equal(img[safe], expected[safe])
    assert safe.mean() > 0.99
