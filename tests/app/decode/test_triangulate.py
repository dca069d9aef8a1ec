"""Triangulation against analytic geometry, with lens distortion on both camera and projector."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from synth import make_calibration

from app.errors import InputError
from app.triangulate import Triangulator, _depth_from_column_moebius


@pytest.fixture(scope="module")
def tri():
    cal = make_calibration(
        cam=(160, 120),
        proj=(256, 192),
        fc=300,
        fp=190,
        cam_dist=np.array([-0.12, 0.05, 0.001, -0.001, 0.0]),
        proj_dist=np.array([0.08, -0.04, 0.0, 0.002, 0.0]),
    )
    return Triangulator(cal, (400.0, 1500.0))


def exact_column(tri, depth):
    cal = tri.calibration
    X = np.concatenate([tri.ray.astype(np.float64) * depth[..., None], depth[..., None]], axis=2).reshape(-1, 3)
    uv, _ = cv2.projectPoints(X, cv2.Rodrigues(cal.R)[0], cal.T, cal.projector_matrix, cal.projector_distortion)
    return uv.reshape(*depth.shape, 2)[..., 0].astype(np.float32)


def test_depth_of_a_curved_surface_is_exact(tri):
    h, w = tri.ray.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    depth = 700.0 + 200.0 * np.sin(xs / 30.0) * np.cos(ys / 40.0)
    col = exact_column(tri, depth)
    got = tri.depth(col)
    assert (got > 0).all()
    # node interpolation is held to 0.01 projector px, ~0.2 mm at 700 mm on this short baseline
    assert np.abs(got - depth).max() < 0.1
    assert np.sqrt(np.mean((got - depth) ** 2)) < 0.03


def _curved_depth(tri):
    h, w = tri.ray.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    return 800.0 + 150.0 * np.sin(xs / 30.0) * np.cos(ys / 40.0)


@pytest.mark.parametrize("proj_dist", [np.zeros(5), np.array([0.035, -0.05, 0.0, 0.0, 0.0])])
def test_closed_form_path_is_exact_where_the_column_is_nearly_moebius(proj_dist):
    # no projector distortion: u(1/Z) is exactly a Moebius map; the virtual rig's mild distortion: nearly
    cal = make_calibration(cam=(160, 120), proj=(256, 192), fc=300, fp=190, proj_dist=proj_dist)
    tri = Triangulator(cal, (600.0, 1000.0))
    assert tri.moebius is not None and tri.moebius_error_px <= 0.005
    depth = _curved_depth(tri)
    got = tri.depth(exact_column(tri, depth))
    assert (got > 0).all()
    assert np.abs(got - depth).max() < (0.01 if not proj_dist.any() else 0.05)
    beyond = exact_column(tri, np.full(depth.shape, 1100.0))
    assert (tri.depth(beyond) == 0).all()


def test_strong_projector_distortion_keeps_the_node_table(tri):
    # the module's calibration bends columns too much over its long depth range for one Moebius map
    assert tri.moebius is None and tri.moebius_error_px > 0.005


def test_rays_are_undistorted(tri):
    cal = tri.calibration
    pts = np.array([[3.0, 7.0], [150.0, 100.0]])
    for x, y in pts:
        r = tri.ray[int(y), int(x)]
        uv, _ = cv2.projectPoints(
            np.array([[r[0], r[1], 1.0]]), np.zeros(3), np.zeros(3), cal.camera_matrix, cal.camera_distortion
        )
        assert np.allclose(uv.ravel(), [x, y], atol=1e-3)


def test_depth_range_masks_and_nan_gives_zero(tri):
    h, w = tri.ray.shape[:2]
    col = exact_column(tri, np.full((h, w), 2000.0))  # beyond far
    assert (tri.depth(col) == 0).all()
    assert (tri.depth(np.full((h, w), np.nan, np.float32)) == 0).all()


def test_point_cloud_is_the_ray_scaled_by_depth(tri):
    h, w = tri.ray.shape[:2]
    depth = np.zeros((h, w), np.float32)
    depth[10, 20] = 800.0
    img = np.zeros((h, w, 3), np.uint8)
    img[10, 20] = (1, 2, 3)
    cloud = tri.points(depth, img)
    assert cloud.xyz.shape == (1, 3)
    np.testing.assert_allclose(cloud.xyz[0], [tri.ray[10, 20, 0] * 800, tri.ray[10, 20, 1] * 800, 800], rtol=1e-6)
    assert cloud.rgb.tolist() == [[1, 2, 3]]


def test_size_mismatch_is_an_input_error(tri):
    with pytest.raises(InputError, match="calibration camera"):
        tri.depth(np.zeros((10, 10), np.float32))


def test_closed_form_pass_gives_no_depth_where_the_column_has_none():
    # u(t) = (a + b t) / (1 + c t): t = (u - a) / (b - c u) must lie in [0, 1]; Z = 1 / (w0 + t w_span)
    w0, w_span = 1.0 / 1000.0, 1.0 / 600.0 - 1.0 / 1000.0
    u = np.array([[5.0, 15.0, 10.0, np.nan, 4.0, 16.0, 5.0]], np.float32)
    a = np.full(u.shape, 5.0, np.float32)
    b = np.array([[10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 0.0]], np.float32)  # last: b - c u = 0 at u = a
    c = np.zeros(u.shape, np.float32)
    out = np.empty(u.shape, np.float32)
    _depth_from_column_moebius(u, a, b, c, w0, w_span, out)
    expect = [1000.0, 600.0, 1.0 / (w0 + 0.5 * w_span), 0.0, 0.0, 0.0, 0.0]  # range ends, middle, NaN, outside, 0/0
    assert np.allclose(out[0], expect, rtol=1e-6, atol=0.0)


@pytest.mark.parametrize("near", [10.0, 50.0, 100.0])
def test_a_near_end_close_to_the_rig_keeps_every_lit_pixel(small_rig, near):
    """The virtual rig's true columns triangulate to its true depth with the near end far in front of the scene.

    A near end of 50 mm used to give no depth at all: far outside the projector's field its distortion polynomial
    folds back, so u(1/Z) was not monotone on any ray and every ray was refused. Only the lit part of a ray counts
    now, and the table spans the depths at which the projector's field is seen at all."""
    rig = small_rig("face", ideal=True)
    rig.render(np.zeros((*rig.projector_size[::-1], 3), np.uint8))
    gt = rig.ground_truth
    lit = gt.lit & (gt.depth > 0)
    tri = Triangulator(rig.calibration, (near, 5000.0))
    assert tri.table_range_mm[0] > near  # nothing is lit at 10-50 mm in front of this camera
    got = tri.depth(gt.column.astype(np.float32))
    assert (got[lit] > 0).all()
    # 33 nodes over 1/Z spread across a 50:1 depth range: ~0.15 px of interpolation, ~0.5 mm at 700 mm
    assert np.abs(got[lit] - gt.depth[lit]).max() < 0.6
    near_range = Triangulator(rig.calibration, rig.depth_range_mm).depth(gt.column.astype(np.float32))
    assert np.abs(near_range[lit] - gt.depth[lit]).max() < 0.02  # the working volume is within the 0.01 px budget


def test_a_depth_range_no_pixel_can_see_is_refused(small_rig):
    rig = small_rig("plane", ideal=True)
    with pytest.raises(InputError, match=r"depth range 1-5 mm: no camera pixel sees the projector"):
        Triangulator(rig.calibration, (1.0, 5.0))
