"""Fusion against the virtual rig's truth: the mesh against the true surface, the poses against the true poses.

Real Open3D throughout (slscan[fusion]); small sequences (a few scans at 640x480, whose decoder is the one the
targets are for), coarse voxels. The meshes are read back with trimesh, which did not write them.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from app.cli import main
from app.fusion import metrics
from app.fusion.registration import rotation_deg
from core.surface_sample import read_surface_sample
from core.trajectory import read_trajectory

pytest.importorskip("open3d")

RENDER = ["sim", "render", "--scheme", "two-shot", "--camera-size", "640x480"]


def _render(tmp_path, name: str, scene: str, cycles: int, *sets: str) -> str:
    out = tmp_path / name
    argv = [*RENDER, "--scene", scene, "--cycles", str(cycles), "--out", str(out)]
    for s in sets:
        argv += ["--set", s]
    assert main(argv) == 0
    return str(out)


@pytest.fixture(scope="module")
def turntable_dump(tmp_path_factory) -> str:
    return _render(tmp_path_factory.mktemp("fuse"), "tt", "turntable", 6, "rotation_deg_per_frame=0.5")


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len([line for line in err if "error" in line]) == 1, err
    return next(line for line in err if "error" in line)


def test_registration_of_true_depth_recovers_the_true_poses(turntable_dump):
    """The tracker and the TSDF on the rig's true depth maps: the registration itself, without the decoder."""
    from app.fusion.fuser import Fuser
    from core.dump import read_dump
    from core.imageio import read_float_tiff

    dump = read_dump(turntable_dump)
    cal = dump.calibration()
    fuser = Fuser(cal, dump.depth_range_mm(), tuple(dump.meta["working_volume_mm"]), voxel_mm=1.0, min_weight=2)
    colour = np.full((*cal.camera_size[::-1], 3), 128, np.uint8)
    for rec in dump.frames[1:]:
        depth = read_float_tiff(f"{turntable_dump}/ground_truth/frames/{Path(rec.file).stem}/depth.tiff")
        assert fuser.add(fuser.scan(depth, colour, rec.frame_id)).ok
    true = {r.frame_id: r.pose for r in read_trajectory(f"{turntable_dump}/ground_truth/poses.csv")}
    first = true[fuser.poses[0].frame_id]
    to_model = np.linalg.inv(first)
    surface = read_surface_sample(f"{turntable_dump}/ground_truth/surface.ply")
    model_pts = surface.points[::50] @ to_model[:3, :3].T + to_model[:3, 3]
    for r in fuser.poses:
        deg, mm = metrics.pose_error(r.pose, to_model @ true[r.frame_id], model_pts)
        assert deg < 0.05 and mm < 0.05, (r.frame_id, deg, mm)
    V = np.asarray(fuser.mesh().vertices) @ first[:3, :3].T + first[:3, 3]
    assert metrics.accuracy(V, surface).mean_mm < 0.15


def test_fuse_builds_a_mesh_on_the_true_surface_and_poses_near_the_true_ones(tmp_path, turntable_dump, capsys):
    out = tmp_path / "model.ply"
    assert main(["fuse", turntable_dump, "--out", str(out), "--voxel-mm", "1", "--min-weight", "2"]) == 0
    assert "fused 11 of 11 scans" in capsys.readouterr().out
    true = read_trajectory(f"{turntable_dump}/ground_truth/poses.csv")  # per frame: camera -> object
    est = read_trajectory(tmp_path / "model.trajectory.csv")  # per scan: camera -> model (the first scan's camera)
    assert [r.frame_id for r in est] == list(range(2, 13)) and {r.status for r in est} == {"ok"}
    by_frame = {r.frame_id: r.pose for r in true}
    first = by_frame[est[0].frame_id]
    to_model = np.linalg.inv(first)  # object -> model
    surface = read_surface_sample(f"{turntable_dump}/ground_truth/surface.ply")
    model_pts = surface.points[::50] @ to_model[:3, :3].T + to_model[:3, 3]
    # the decoder's depth errors are partly fixed in the camera's frame and hold the registration back (docs/
    # performance.md, "Fusion"): the bound is on that, loose, and on following the turn at all
    for r in est:
        true_pose = to_model @ by_frame[r.frame_id]
        deg, mm = metrics.pose_error(r.pose, true_pose, model_pts)
        assert deg < 2.0 and mm < 1.5, (r.frame_id, deg, mm)
    turned = rotation_deg(est[-1].pose[:3, :3])
    assert 3.0 < turned < 6.0, turned  # 5 degrees turned
    for path in (tmp_path / "model.ply", tmp_path / "model.obj"):
        mesh = trimesh.load(path, process=False)
        assert len(mesh.faces) > 5000
        colours = np.asarray(mesh.visual.vertex_colors)[:, :3]
        assert colours.std() > 5  # coloured, not one grey
        V = np.asarray(mesh.vertices) @ first[:3, :3].T + first[:3, 3]  # model -> object frame
        err = metrics.vertex_errors(V, surface)
        assert err.mean() < 0.3 and np.percentile(err, 90) < 0.6, (path.name, err.mean())


def test_fuse_without_calibration_is_one_line_and_exit_2(tmp_path, turntable_dump, capsys):
    import shutil

    bad = tmp_path / "nocal"
    shutil.copytree(turntable_dump, bad)
    meta = yaml.safe_load((bad / "dump.yaml").read_text())
    del meta["calibration"]
    (bad / "dump.yaml").write_text(yaml.safe_dump(meta))
    assert main(["fuse", str(bad), "--out", str(tmp_path / "m.ply")]) == 2
    assert "no calibration" in _one_error_line(capsys)
    assert not (tmp_path / "m.ply").exists()


def test_fuse_with_too_few_scans_is_one_line_and_exit_2(tmp_path, capsys):
    dump = _render(tmp_path, "one", "turntable", 1, "rotation_deg_per_frame=0.5")
    capsys.readouterr()
    assert main(["fuse", dump, "--out", str(tmp_path / "m.ply")]) == 2
    assert "at least 2 scans" in _one_error_line(capsys)


def test_a_scan_failing_registration_is_one_line_and_the_partial_model_is_saved(tmp_path, capsys):
    dump = _render(tmp_path, "fast", "turntable", 2, "rotation_deg_per_frame=30")  # 30 deg a frame: no overlap
    capsys.readouterr()
    out = tmp_path / "part.ply"
    argv = ["fuse", dump, "--out", str(out), "--voxel-mm", "2", "--min-weight", "1", "--max-dropped", "0"]
    assert main([*argv, "--save-partial"]) == 2
    line = _one_error_line(capsys)
    assert "failed to register" in line and "tracking lost" in line
    mesh = trimesh.load(out, process=False)  # the first scan's model
    assert len(mesh.faces) > 1000
    rows = read_trajectory(tmp_path / "part.trajectory.csv")
    assert [r.status for r in rows] == ["ok", "dropped"]


def test_a_voxel_too_small_for_the_memory_is_one_line_and_exit_2(tmp_path, turntable_dump, capsys):
    assert main(["fuse", turntable_dump, "--out", str(tmp_path / "m.ply"), "--voxel-mm", "0.001"]) == 2
    line = _one_error_line(capsys)
    assert "--voxel-mm 0.001" in line and "GiB" in line


def test_fusion_without_open3d_names_the_extra(tmp_path, turntable_dump, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)  # as if not installed: `import open3d` raises ImportError
    assert main(["fuse", turntable_dump, "--out", str(tmp_path / "m.ply")]) == 2
    assert "slscan[fusion]" in _one_error_line(capsys)


def test_texture_frames_colour_the_model_with_the_objects_own_red(tmp_path, turntable_dump, capsys):
    # the same turn with a white frame after every 3 pattern frames (slscan sim render --texture-every)
    textured = tmp_path / "tx"
    argv = [*RENDER, "--scene", "turntable", "--cycles", "6", "--texture-every", "3", "--out", str(textured)]
    assert main([*argv, "--set", "rotation_deg_per_frame=0.5"]) == 0
    from core.dump import read_dump

    dump = read_dump(textured)
    assert [f.pattern for f in dump.frames][:8] == [0, 1, 0, 2, 1, 0, 1, 2]  # (tag 2: the texture frame)
    red = {}
    for name, folder in (("pair", turntable_dump), ("texture", textured)):
        out = tmp_path / f"{name}.ply"
        assert main(["fuse", str(folder), "--out", str(out), "--voxel-mm", "1", "--min-weight", "2"]) == 0
        colours = np.asarray(trimesh.load(out, process=False).visual.vertex_colors)[:, :3].astype(float)
        red[name] = colours[:, 0].mean()
    assert "fused 8 of 8 scans" in capsys.readouterr().out  # 11 sliding pairs, 3 broken by the texture frames
    # a two-shot pair never lights red: without texture frames the model's red is the ambient light alone
    assert red["texture"] > 1.8 * red["pair"], red
