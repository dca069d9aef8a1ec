"""The operator view's 3D point view (app/pointview.py): points land where a pinhole puts them,
nearer points hide farther ones, an empty cloud gives a blank panel."""

from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest

from app.export import depth_preview
from app.pointview import PointView, decimate, decimated_rays, depth_colours, render_points

K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])
CAM = (640, 480)


def unique_colours(n: int) -> np.ndarray:
    i = np.arange(1, n + 1)
    return np.stack([i % 251, (i // 251) % 251 + 1, 200 + i % 50], axis=1).astype(np.uint8)


def predicted_pixels(xyz: np.ndarray, view: PointView) -> np.ndarray:
    R, t = view.extrinsics()
    uv, _ = cv2.projectPoints(xyz.astype(np.float64), cv2.Rodrigues(R)[0], t, view.camera_matrix, None)
    return uv.reshape(-1, 2)


@pytest.mark.parametrize("yaw, pitch", [(0.0, 0.0), (25.0, -10.0), (-40.0, 15.0)])
def test_plane_points_land_where_the_pinhole_puts_them(yaw, pitch):
    view = PointView.for_camera(K, CAM, (320, 240), 800.0).turned(yaw, pitch)
    # a tilted plane of points 12 mm apart: far enough that no two share a pixel
    gx, gy = np.meshgrid(np.arange(-150, 151, 12.0), np.arange(-110, 111, 12.0))
    xyz = np.stack([gx.ravel(), gy.ravel(), 800 + 0.3 * gx.ravel()], axis=1).astype(np.float32)
    rgb = unique_colours(len(xyz))
    img = render_points(xyz, rgb, view)
    uv = predicted_pixels(xyz, view)
    inside = (uv[:, 0] > 0) & (uv[:, 0] < 319) & (uv[:, 1] > 0) & (uv[:, 1] < 239)
    clear = np.all(np.abs(uv % 1 - 0.5) > 0.02, axis=1)  # not on a rounding tie
    check = inside & clear
    assert check.sum() > 200
    u, v = np.rint(uv[check]).astype(int).T
    np.testing.assert_array_equal(img[v, u], rgb[check])
    assert img.any(axis=2).sum() == inside.sum()  # every visible point drawn once, nothing else


def test_front_view_is_the_camera_picture_scaled():
    """At yaw = pitch = 0 a point seen at camera pixel (x, y) lands at ((x + .5) s - .5, (y + .5) s - .5)."""
    view = PointView.for_camera(K, CAM, (320, 240), 700.0)
    pix = np.array([[100.0, 50.0], [321.0, 241.0], [601.0, 431.0]])
    z = np.array([500.0, 900.0, 1200.0])
    xyz = np.column_stack([(pix[:, 0] - K[0, 2]) / K[0, 0] * z, (pix[:, 1] - K[1, 2]) / K[1, 1] * z, z])
    img = render_points(xyz.astype(np.float32), np.full((3, 3), 255, np.uint8), view)
    ys, xs = np.nonzero(img.any(axis=2))
    assert sorted(zip(xs.tolist(), ys.tolist(), strict=True)) == [(50, 25), (160, 120), (300, 215)]


@pytest.mark.parametrize("order", ["near first", "far first"])
def test_nearer_points_hide_farther_ones(order):
    view = PointView.for_camera(K, CAM, (320, 240), 800.0).turned(30.0, 0.0)
    R, t = view.extrinsics()
    # points on one viewing ray of the orbiting view camera: X = R^T (d * ray - t)
    ray = np.array([0.05, -0.02, 1.0])
    depths = np.array([600.0, 700.0, 900.0])
    xyz = np.array([R.T @ (d * ray - t) for d in depths], np.float32)
    rgb = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], np.uint8)
    if order == "far first":
        xyz, rgb = xyz[::-1].copy(), rgb[::-1].copy()
    img = render_points(xyz, rgb, view)
    lit = np.argwhere(img.any(axis=2))
    assert len(lit) == 1
    assert tuple(img[tuple(lit[0])]) == (255, 0, 0)  # the nearest of the three


def test_cube_front_face_hides_its_back_face():
    view = PointView.for_camera(K, CAM, (320, 240), 800.0)
    s = np.arange(-60, 61, 1.0)
    a, b = np.meshgrid(s, s)
    front = np.stack([a.ravel(), b.ravel(), np.full(a.size, 740.0)], axis=1)
    back = np.stack([a.ravel(), b.ravel(), np.full(a.size, 860.0)], axis=1)
    xyz = np.concatenate([back, front]).astype(np.float32)  # the back face first: order must not matter
    rgb = np.concatenate([np.tile([0, 0, 255], (len(back), 1)), np.tile([255, 0, 0], (len(front), 1))])
    img = render_points(xyz, rgb.astype(np.uint8), view)
    # the front face covers the back face's silhouette: inside it, only red
    uv = predicted_pixels(back, view)
    u0, v0 = np.ceil(uv.min(axis=0)).astype(int)
    u1, v1 = np.floor(uv.max(axis=0)).astype(int)
    inner = img[v0 : v1 + 1, u0 : u1 + 1]
    assert inner.shape[0] > 10 and (inner == [255, 0, 0]).all()
    # turned, the cube's far face shows past the front one on one side
    turned = render_points(xyz, rgb.astype(np.uint8), view.turned(35.0, 0.0))
    assert (turned == [0, 0, 255]).all(axis=2).sum() > 100 and (turned == [255, 0, 0]).all(axis=2).sum() > 100


def test_empty_cloud_and_points_behind_give_a_blank_panel():
    view = PointView.for_camera(K, CAM, (160, 120), 800.0)
    blank = render_points(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), view)
    assert blank.shape == (120, 160, 3) and blank.dtype == np.uint8 and not blank.any()
    behind = np.array([[0, 0, -500.0], [10, 10, 0.0]], np.float32)
    assert not render_points(behind, np.full((2, 3), 255, np.uint8), view).any()


def test_decimate_gives_the_triangulated_points_of_every_step_th_pixel():
    rng = np.random.default_rng(3)
    h, w = 48, 64
    ray = np.stack(np.meshgrid((np.arange(w) - 31.5) / 60, (np.arange(h) - 23.5) / 60), axis=-1).astype(np.float32)
    depth = rng.uniform(500, 900, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.3] = 0
    image = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    xyz, rgb = decimate(depth, decimated_rays(ray, 4), image, 4)
    ys, xs = np.nonzero(depth[::4, ::4] > 0)
    ys, xs = ys * 4, xs * 4
    z = depth[ys, xs]
    np.testing.assert_allclose(xyz, np.column_stack([ray[ys, xs, 0] * z, ray[ys, xs, 1] * z, z]), rtol=1e-6)
    np.testing.assert_array_equal(rgb, image[ys, xs])
    _, rgb16 = decimate(depth, decimated_rays(ray, 4), image.astype(np.uint16) << 8, 4)
    np.testing.assert_array_equal(rgb16, rgb)


def test_depth_colours_are_the_depth_panels():
    z = np.random.default_rng(5).uniform(300, 1300, 4000).astype(np.float32)
    xyz = np.column_stack([z * 0, z * 0, z])
    for rng in ((500.0, 1000.0), None):
        np.testing.assert_array_equal(depth_colours(xyz, rng), depth_preview(z.reshape(1, -1), rng)[0])


def test_orbit_swings_slowly_and_keys_turn():
    view = PointView.for_camera(K, CAM, (160, 120), 800.0)
    yaws = [view.orbit(t).yaw_deg for t in np.linspace(0, 8, 81)]
    assert max(yaws) == pytest.approx(30) and min(yaws) == pytest.approx(-30)
    assert max(abs(a - b) for a, b in itertools.pairwise(yaws)) < 3  # slow: < 3 degrees per 0.1 s
    turned = view.turned(10, 100)
    assert (turned.yaw_deg, turned.pitch_deg) == (10, 80)
