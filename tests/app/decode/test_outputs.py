"""What `slscan decode` writes beside the depth: PLY normals against the true surface, the 16-bit PNG read back by
Open3D at the scale its sidecar states, and the scan_NNNNNN.yaml sidecar's fields."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from app.dump import DumpWriter
from app.export import read_ply
from app.imageio import read_float_tiff
from app.patterns import two_shot_patterns
from core.calibration import Calibration
from core.depth_message import calibration_digest
from core.scan_sidecar import read_scan_info
from core.wallclock import parse_wall_clock


def _render_dump(rig, folder):
    ps = two_shot_patterns(rig.projector_size)
    with DumpWriter(folder, ps, rig.calibration, rig.depth_range_mm) as w:
        for i, p in enumerate([0, 1]):
            w.add(rig.render(ps.images[p]), p, 40 + i, 5_000_000 + 16_666_667 * i)
    return folder


@pytest.fixture(scope="module")
def decoded(tmp_path_factory, small_rig, run_cli_module):
    """scene -> (rig, decode output folder): a two-frame dump of the scene, decoded with --png16."""
    out = {}
    for scene in ("plane", "cube"):
        rig = small_rig(scene)
        base = tmp_path_factory.mktemp(scene)
        dump = _render_dump(rig, base / "dump")
        r = run_cli_module("decode", dump, "--out", base / "out", "--workers", "1", "--png16")
        assert r.returncode == 0, r.stderr
        out[scene] = (rig, base / "out", dump)
    return out


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


def _true_cube_normals(rig, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the cube face's normal facing the camera, whether the point is on the cube and 3 mm inside a face) of each
    camera-frame point (from the scene: the box's local axes)."""
    box = rig.scene.shapes[0]
    local = box.point_to_local(points.astype(np.float64))
    half = np.asarray(box.half)
    axis = np.argmax(np.abs(local) / half, axis=1)
    rows = np.arange(len(points))
    on_box = np.all(np.abs(local) <= half + 0.5, axis=1)
    inner = np.sort(half - np.abs(local), axis=1)[:, 1] > 3.0  # the two in-face coordinates away from the edges
    n = box.R[:, axis].T * np.sign(local[rows, axis])[:, None]
    n[np.sum(n * points, axis=1) > 0] *= -1
    return n, on_box & inner


def test_plane_normals_face_the_camera_along_the_true_normal(decoded):
    _, out, _ = decoded["plane"]
    cloud = read_ply(out / "cloud_000000.ply")
    assert cloud.normals is not None and cloud.normals.shape == cloud.xyz.shape
    has = np.linalg.norm(cloud.normals, axis=1) > 0.5
    assert has.mean() > 0.95
    np.testing.assert_allclose(np.linalg.norm(cloud.normals[has], axis=1), 1.0, atol=1e-5)
    true = np.array([[0.0, 0.0, -1.0]])  # the plane faces the camera (scene file)
    ang = _angles_deg(cloud.normals[has], true)
    # (the decoded depth's own ripple, ~0.4 mm across a stripe period at 320x240, is what the spread measures)
    assert np.median(ang) < 5.0, np.median(ang)
    mean = cloud.normals[has].mean(axis=0)
    assert _angles_deg(mean[None] / np.linalg.norm(mean), true)[0] < 0.5


def test_cube_normals_follow_each_face(decoded):
    rig, out, _ = decoded["cube"]
    cloud = read_ply(out / "cloud_000000.ply")
    depth = read_float_tiff(out / "depth_000000.tiff")
    gt_points = rig.ground_truth.points[depth > 0]  # (the PLY's points are the pixels with depth, row-major)
    true, inner = _true_cube_normals(rig, gt_points)
    has = np.linalg.norm(cloud.normals, axis=1) > 0.5
    sel = inner & has
    assert sel.sum() > 1000
    ang = _angles_deg(cloud.normals[sel], true[sel])
    assert np.median(ang) < 3.5 and np.percentile(ang, 75) < 7.0, (np.median(ang), np.percentile(ang, 75))
    # three faces are seen, each with its own normal
    faces = {tuple(np.round(t, 3)) for t in true[sel]}
    assert len(faces) == 3


def test_png16_reads_back_in_open3d_at_the_stated_depth_scale(decoded):
    o3d = pytest.importorskip("open3d")
    _, out, _ = decoded["plane"]
    info = read_scan_info(out / "scan_000000.yaml")
    assert info.files["depth_png"] == "depth_000000.png" and info.depth_scale == 10000
    depth = read_float_tiff(out / info.files["depth"])
    png = o3d.io.read_image(str(out / info.files["depth_png"]))
    colour = o3d.geometry.Image(np.zeros((*depth.shape, 3), np.uint8))
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        colour, png, depth_scale=info.depth_scale, depth_trunc=100.0, convert_rgb_to_intensity=False
    )
    metres = np.asarray(rgbd.depth)
    assert metres.shape == depth.shape
    ok = depth > 0
    assert np.array_equal(metres > 0, ok)
    assert np.max(np.abs(metres[ok] * 1000.0 - depth[ok])) <= 0.05 + 1e-3  # half a 0.1 mm step


def test_scan_sidecar_fields(decoded):
    rig, out, dump = decoded["plane"]
    info = read_scan_info(out / "scan_000000.yaml")
    raw = yaml.safe_load((out / "scan_000000.yaml").read_text())
    assert raw["units"] == "mm" and raw["depth_none"] == 0 and raw["format"] == "slscan-scan"
    assert info.scheme == "two-shot" and info.frame_ids == (40, 41)
    assert info.timestamps_ns == (5_000_000, 21_666_667)
    assert info.camera_size == tuple(rig.calibration.camera_size)
    assert set(info.files) == {"depth", "depth_png", "cloud", "stripes"}
    assert all((out / f).is_file() for f in info.files.values())
    assert info.texture_frame_id is None
    recorded = parse_wall_clock(yaml.safe_load((dump / "dump.yaml").read_text())["recorded_utc"], "dump")
    assert parse_wall_clock(info.wall_clock_start, "scan") == pytest.approx(recorded, abs=2e6)
    cal = Calibration.load(out / info.calibration)
    assert info.calibration_sha256 == calibration_digest(cal) == calibration_digest(rig.calibration)
    assert info.calibration_source == str((dump / "calibration.yaml").resolve())


@pytest.mark.parametrize(
    "edit, field",
    [
        (("depth_scale: 10000.0", "depth_scale: -1"), "depth_scale"),
        (("depth_scale: 10000.0", "depth_scale: null"), "depth_scale"),
        (("units: mm", "units: m"), "units"),
        (("- 40\n", "- x\n"), "frame_ids"),
        (("wall_clock_start: '", "wall_clock_start: 'noon "), "wall_clock_start"),
        (("  cloud: cloud_000000.ply", "  cloud: ../cloud.ply"), "files.cloud"),
    ],
)
def test_a_malformed_sidecar_is_refused_naming_the_field(decoded, tmp_path, edit, field):
    from core.errors import InputError

    text = (decoded["plane"][1] / "scan_000000.yaml").read_text()
    assert edit[0] in text
    bad = tmp_path / "scan.yaml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(InputError) as err:
        read_scan_info(bad)
    assert str(bad) in str(err.value) and field in str(err.value) and "\n" not in str(err.value)


def test_a_dump_from_before_recorded_utc_decodes_as_before_with_no_wall_clock(decoded, tmp_path, run_cli_module):
    import shutil

    _, _, dump = decoded["plane"]
    old = tmp_path / "old"
    shutil.copytree(dump, old)
    index = old / "dump.yaml"
    index.write_text("".join(line for line in index.read_text().splitlines(True) if "recorded_utc" not in line))
    r = run_cli_module("decode", old, "--out", tmp_path / "out", "--workers", "1")
    assert r.returncode == 0, r.stderr
    info = read_scan_info(tmp_path / "out" / "scan_000000.yaml")
    assert info.wall_clock_start is None and info.frame_ids == (40, 41) and info.texture_frame_id is None
    np.testing.assert_array_equal(
        read_float_tiff(tmp_path / "out" / "depth_000000.tiff"),
        read_float_tiff(decoded["plane"][1] / "depth_000000.tiff"),
    )
