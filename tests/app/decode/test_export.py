"""Exports: PLY and TIFF round trips, stripe pseudo-colours, depth PNG."""

from __future__ import annotations

import numpy as np

from app.export import depth_preview, read_ply, stripe_colours, write_depth_png16, write_depth_tiff, write_ply
from app.imageio import read_float_tiff, read_rgb
from app.triangulate import PointCloud


def test_ply_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    cloud = PointCloud(rng.normal(0, 500, (1000, 3)).astype(np.float32), rng.integers(0, 256, (1000, 3), np.uint8))
    write_ply(tmp_path / "c.ply", cloud)
    back = read_ply(tmp_path / "c.ply")
    np.testing.assert_array_equal(back.xyz, cloud.xyz)
    np.testing.assert_array_equal(back.rgb, cloud.rgb)
    head = (tmp_path / "c.ply").read_bytes()[:300].decode("ascii", "replace")
    assert "element vertex 1000" in head and "property uchar red" in head and "property float x" in head
    assert (tmp_path / "c.ply").stat().st_size == head.index("end_header\n") + 11 + 1000 * 15


def test_empty_ply(tmp_path):
    write_ply(tmp_path / "e.ply", PointCloud(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)))
    assert len(read_ply(tmp_path / "e.ply").xyz) == 0


def test_depth_tiff_round_trip(tmp_path):
    d = np.random.default_rng(1).uniform(400, 900, (48, 64)).astype(np.float32)
    d[:5] = 0
    write_depth_tiff(tmp_path / "d.tiff", d)
    np.testing.assert_array_equal(read_float_tiff(tmp_path / "d.tiff"), d)


def test_depth_png16_in_tenths_of_mm(tmp_path):
    d = np.array([[0.0, 123.44, 6553.5]], np.float32)
    write_depth_png16(tmp_path / "d.png", d)
    back = read_rgb(tmp_path / "d.png")[..., 0]
    assert back.dtype == np.uint16 and back.tolist() == [[0, 1234, 65535]]


def test_stripe_colours_differ_between_neighbours_and_black_for_none():
    s = np.array([[-1, 0, 1, 2, 3, 255, 256]])
    rgb = stripe_colours(s).astype(int)
    assert rgb[0, 0].tolist() == [0, 0, 0]
    for i in range(1, 6):
        assert np.abs(rgb[0, i] - rgb[0, i + 1]).sum() > 60


def test_depth_preview_black_where_none():
    d = np.array([[0, 500, 900]], np.float32)
    p = depth_preview(d, (500, 900))
    assert p[0, 0].tolist() == [0, 0, 0] and p[0, 1].tolist() != p[0, 2].tolist()


def test_ply_round_trip_with_normals_in_open3d_layout(tmp_path):
    rng = np.random.default_rng(2)
    n = rng.normal(size=(500, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:10] = 0  # (no normal)
    cloud = PointCloud(rng.normal(0, 500, (500, 3)).astype(np.float32), rng.integers(0, 256, (500, 3), np.uint8), n)
    write_ply(tmp_path / "n.ply", cloud)
    head = (tmp_path / "n.ply").read_bytes()[:400].decode("ascii", "replace")
    props = [line.split()[-1] for line in head.splitlines() if line.startswith("property")]
    assert props == ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"]
    back = read_ply(tmp_path / "n.ply")
    np.testing.assert_array_equal(back.normals, n)
    np.testing.assert_array_equal(back.xyz, cloud.xyz)
    np.testing.assert_array_equal(back.rgb, cloud.rgb)


def test_depth_png16_scale_is_units_per_metre_and_out_of_range_is_none(tmp_path):
    d = np.array([[0.0, 123.4, 65535.0, 70000.0, np.nan]], np.float32)
    write_depth_png16(tmp_path / "mm.png", d, depth_scale=1000)  # Open3D's default: mm
    back = read_rgb(tmp_path / "mm.png")[..., 0]
    assert back.tolist() == [[0, 123, 65535, 0, 0]]
    write_depth_png16(tmp_path / "t.png", np.array([[6600.0]], np.float32))  # beyond 6.5535 m at 0.1 mm
    assert read_rgb(tmp_path / "t.png")[..., 0].tolist() == [[0]]
