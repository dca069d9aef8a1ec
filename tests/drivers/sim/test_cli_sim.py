"""`slscan sim render` writes a dump with ground truth that reads back; bad input is one line, exit 2."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from app.cli import main
from core.dump import read_dump
from core.imageio import read_float_tiff, read_rgb
from core.patterns import two_shot_patterns
from drivers.sim.rig import VirtualRig


def test_sim_render_writes_a_dump_and_ground_truth_that_read_back(run_cli, tmp_path: Path) -> None:
    out = tmp_path / "dump"
    res = run_cli("sim", "render", "--scene", "plane", "--scheme", "two-shot", "--ideal", "--out", out)
    assert res.returncode == 0, res.stderr
    dump = read_dump(out)
    assert dump.scheme == "two-shot" and [f.pattern for f in dump.frames] == [0, 1]
    rig = VirtualRig.from_preset("plane", ideal=True, camera_size=(160, 120))
    assert dump.depth_range_mm() == rig.depth_range_mm
    cal = dump.calibration()
    truth = VirtualRig.from_preset("plane", ideal=True).geometry.calibration()
    assert np.allclose(cal.R, truth.R) and np.allclose(cal.T, truth.T)
    assert np.allclose(cal.camera_matrix, truth.camera_matrix) and np.allclose(cal.color_mixing, np.eye(3))
    gt = out / "ground_truth"
    depth = read_float_tiff(gt / "depth.tiff")
    col = read_float_tiff(gt / "column.tiff")
    row = read_float_tiff(gt / "row.tiff")
    lit = read_rgb(gt / "lit.png", grey=True)
    assert depth.shape == col.shape == row.shape == lit.shape == (480, 640)
    assert np.allclose(depth, 720.0) and set(np.unique(lit)) == {255}
    # frame i is pattern i seen through the ground-truth column/row (ideal white plane)
    pats = two_shot_patterns((1024, 768)).images
    c, r = col.astype(np.float64), row.astype(np.float64)
    safe = (np.abs(c % 1 - 0.5) > 1e-3) & (np.abs(r % 1 - 0.5) > 1e-3)
    for i, pat in enumerate(pats):
        frame = dump.load_frame(i)
        expected = pat[np.floor(r + 0.5).astype(int), np.floor(c + 0.5).astype(int)]
        assert np.array_equal(frame[safe], expected[safe])


def test_sim_render_16_bit_with_overrides(run_cli, tmp_path: Path) -> None:
    out = tmp_path / "d16"
    res = run_cli(
        "sim", "render", "--scene", "steps", "--scheme", "two-shot", "--camera-size", "320x240",
        "--bit-depth", "16", "--set", "ambient=0.2", "--set", "noise=false", "--out", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    dump = read_dump(out)
    frame = dump.load_frame(0)
    assert frame.dtype == np.uint16 and frame.shape == (240, 320, 3)
    lit = read_rgb(out / "ground_truth" / "lit.png", grey=True)
    col = read_float_tiff(out / "ground_truth" / "column.tiff")
    assert 0 < (lit == 255).mean() < 1  # the steps shadow part of the scene
    assert np.array_equal(np.isnan(col), lit == 0)


def test_sim_scenes_lists_the_presets(run_cli) -> None:
    res = run_cli("sim", "scenes")
    assert res.returncode == 0
    names = [line.split()[0] for line in res.stdout.splitlines()]
    assert {"plane", "face", "colour_panel", "cube", "cylinder", "steps", "checkerboard"} <= set(names)


def one_line_exit_2(res) -> str:
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    return res.stderr


def in_process(capsys, *args: object) -> str:
    """The CLI's main() in this process (fast); same exit status and stderr as the console script."""
    code = main([str(a) for a in args])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    return err


def test_unknown_scene_is_one_line_and_exit_2(run_cli, tmp_path: Path) -> None:
    msg = one_line_exit_2(run_cli("sim", "render", "--scene", "nope", "--scheme", "two-shot", "--out", tmp_path / "a"))
    assert "unknown scene 'nope'" in msg and "plane" in msg
    assert not (tmp_path / "a").exists()


def test_bad_scene_file_impossible_set_up_and_bad_options_are_one_line(capsys, tmp_path: Path) -> None:
    render = ("sim", "render", "--scheme", "two-shot", "--scene")
    bad = tmp_path / "bad.yaml"
    bad.write_text("description: x\ndepth_range_mm: [600, 900]\nobjects:\n  - {type: sphere, center: [0, 0, 700]}\n")
    msg = in_process(capsys, *render, bad, "--out", tmp_path / "b")
    assert "bad.yaml" in msg and "'objects[0].radius'" in msg
    behind = tmp_path / "behind.yaml"
    behind.write_text(
        "description: x\ndepth_range_mm: [600, 900]\nobjects:\n  - {type: sphere, center: [0, 0, -700], radius: 5}\n"
    )
    assert "impossible set-up" in in_process(capsys, *render, behind, "--out", tmp_path / "c")
    msg = in_process(capsys, *render, "plane", "--set", "bit_depth=10", "--out", tmp_path / "d")
    assert "bit_depth" in msg
    assert "--set" in in_process(capsys, *render, "plane", "--set", "ambient", "--out", tmp_path / "e")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("keep me")
    assert "never overwritten" in in_process(capsys, *render, "plane", "--out", tmp_path / "full")
    assert (tmp_path / "full" / "x").read_text() == "keep me"
    for name in "bcde":
        assert not (tmp_path / name).exists()


def test_sim_render_with_motion_writes_ground_truth_per_frame(capsys, tmp_path: Path) -> None:
    out = tmp_path / "moving"
    args = ["sim", "render", "--scene", "cube", "--scheme", "two-shot", "--camera-size", "160x120", "--ideal"]
    assert main([*args, "--set", "motion_mm_per_frame=[0, 0, 4]", "--cycles", "2", "--out", str(out)]) == 0
    dump = read_dump(out)
    assert len(dump.frames) == 4
    depths = [read_float_tiff(out / "ground_truth" / "frames" / f"{i:06d}" / "depth.tiff") for i in range(4)]
    centre = [d[40:80, 60:100][d[40:80, 60:100] > 0].min() for d in depths]
    assert np.allclose(np.diff(centre), 4.0, atol=0.2)  # the cube moves 4 mm away per frame
    assert np.array_equal(read_float_tiff(out / "ground_truth" / "depth.tiff"), depths[-1])


def test_sim_render_of_the_turntable_writes_each_frames_truth(capsys, tmp_path: Path) -> None:
    out = tmp_path / "turning"
    args = ["sim", "render", "--scene", "turntable", "--scheme", "two-shot", "--camera-size", "160x120"]
    assert main([*args, "--set", "rotation_deg_per_frame=2", "--cycles", "2", "--out", str(out)]) == 0
    assert len(read_dump(out).frames) == 4
    depths = [read_float_tiff(out / "ground_truth" / "frames" / f"{i:06d}" / "depth.tiff") for i in range(4)]
    assert all(not np.array_equal(a, b) for a, b in itertools.pairwise(depths))  # the bust turns every frame
    rig = VirtualRig.from_preset("turntable", camera_size=(160, 120), rotation_deg_per_frame=2)
    for i in range(4):
        rig.render(None)
        assert np.array_equal(rig.ground_truth.depth, depths[i])
    bad = in_process(capsys, *args, "--set", "rotation_axis=[0, 0, 0]", "--out", tmp_path / "bad")
    assert "'rotation_axis'" in bad and not (tmp_path / "bad").exists()
