"""`slscan replay DUMP --fuse`: live fusion over a recorded dump, at its recorded pace, against the rig's truth.

The dump is a rendered turntable whose timestamps are rewritten to a slow camera, so that the fusion thread (at a
lower priority than capture and decode) has time for most scans even beside other work: nearly every scan is
tracked (the rest counted late), none fails, and the model and the trajectory lie on the true ones, whether the
frames are read from their files as they are played or all read first (`--preload`, as `slscan bench --fusion-live`
plays them). Real Open3D; the mesh is read back with trimesh.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import trimesh
import yaml

from app.cli import main
from app.fusion import metrics
from core.surface_sample import read_surface_sample
from core.trajectory import read_trajectory

pytest.importorskip("open3d")

FRAME_NS = 150_000_000  # the slow camera: a frame every 150 ms


@pytest.fixture(scope="module")
def slow_turntable(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("replay-fuse") / "tt"
    argv = ["sim", "render", "--scene", "turntable", "--scheme", "two-shot", "--camera-size", "640x480"]
    assert main([*argv, "--cycles", "8", "--set", "rotation_deg_per_frame=0.5", "--out", str(out)]) == 0
    meta = yaml.safe_load((out / "dump.yaml").read_text())
    for i, f in enumerate(meta["frames"]):
        f["timestamp_ns"] = i * FRAME_NS
    (out / "dump.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    return str(out)


@pytest.mark.parametrize("preload", [False, True], ids=["from-files", "preloaded"])
def test_replay_fuses_every_scan_onto_the_true_surface(tmp_path, slow_turntable, capsys, preload):
    out = tmp_path / "last"
    argv = ["replay", slow_turntable, "--headless", "--realtime", "--fuse", "--voxel-mm", "1", "--out", str(out)]
    argv += ["--preload"] if preload else []
    assert main(argv) == 0
    text = capsys.readouterr().out
    m = re.search(r"fusion: (\d+) of (\d+) scans tracked \((\d+) late\), (\d+) integrated .* (\d+) failed", text)
    assert m, text
    tracked, offered, late, integrated, failed = map(int, m.groups())
    assert offered == 15 and tracked + late == offered and failed == 0, text  # 16 frames: 15 sliding pairs
    assert tracked >= 10 and integrated >= 5, text
    true = {r.frame_id: r.pose for r in read_trajectory(f"{slow_turntable}/ground_truth/poses.csv")}
    est = read_trajectory(out / "model.trajectory.csv")
    assert len(est) == tracked and {r.status for r in est} == {"ok"}
    assert all(2 <= r.frame_id <= 16 for r in est) and sorted({r.frame_id for r in est}) == [r.frame_id for r in est]
    first = true[est[0].frame_id]
    to_model = np.linalg.inv(first)
    surface = read_surface_sample(f"{slow_turntable}/ground_truth/surface.ply")
    model_pts = surface.points[::50] @ to_model[:3, :3].T + to_model[:3, 3]
    for r in est:
        deg, mm = metrics.pose_error(r.pose, to_model @ true[r.frame_id], model_pts)
        assert deg < 2.0 and mm < 1.5, (r.frame_id, deg, mm)
    mesh = trimesh.load(out / "model.ply", process=False)
    V = np.asarray(mesh.vertices) @ first[:3, :3].T + first[:3, 3]  # model -> object frame
    err = metrics.vertex_errors(V, surface)
    assert len(mesh.faces) > 1000 and err.mean() < 0.3, err.mean()


def test_a_dump_with_a_bad_working_volume_is_one_line_and_exit_2(tmp_path, slow_turntable, capsys):
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(slow_turntable, bad)
    meta = yaml.safe_load((bad / "dump.yaml").read_text())
    meta["working_volume_mm"] = [-80, 80, 70, -90, 650, 850]  # y0 > y1
    (bad / "dump.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    for argv in (["replay", str(bad), "--headless", "--fuse"], ["fuse", str(bad), "--out", str(tmp_path / "m.ply")]):
        assert main([*argv]) == 2
        err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
        assert len(err) == 1 and "dump.yaml: field 'working_volume_mm'" in err[0] and "y0 < y1" in err[0], err
    assert not (tmp_path / "m.ply").exists()
