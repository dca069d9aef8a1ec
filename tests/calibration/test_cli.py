"""`slscan calibrate`: --auto on the virtual rig, --from repeats it, bad input gives one line and exit 2."""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest
import yaml

from app.bench.calibration import GEOMETRY_TARGETS as TARGETS
from calibration.board import Board
from calibration.validate import compare
from core.calibration import Calibration
from core.dump import DumpWriter, read_dump
from core.patterns import graycode_patterns


def one_line_error(proc) -> str:
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    return lines[0]


def test_from_a_folder_that_is_not_a_capture(run_cli, tmp_path):
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "notes.txt").write_text("hello")
    err = one_line_error(run_cli("calibrate", "--from", tmp_path / "junk", "--out", tmp_path / "c.yaml"))
    assert "not a calibration capture" in err and "board.yaml" in err
    err = one_line_error(run_cli("calibrate", "--from", tmp_path / "nope", "--out", tmp_path / "c.yaml"))
    assert "nope" in err and "not a folder" in err
    (tmp_path / "junk" / "board.yaml").write_text(yaml.safe_dump({"type": "checkerboard", "rows": 7, "cols": 10}))
    err = one_line_error(run_cli("calibrate", "--from", tmp_path / "junk", "--out", tmp_path / "c.yaml"))
    assert "board.yaml: missing field 'square_mm'" in err
    Board("checkerboard", 7, 10, 12.0).save(tmp_path / "junk" / "board.yaml")
    err = one_line_error(run_cli("calibrate", "--from", tmp_path / "junk", "--out", tmp_path / "c.yaml"))
    assert "no pose_000/" in err
    (tmp_path / "junk" / "pose_000").mkdir()
    err = one_line_error(run_cli("calibrate", "--from", tmp_path / "junk", "--out", tmp_path / "c.yaml"))
    assert "pose_000: not a frame dump" in err
    assert not (tmp_path / "c.yaml").exists()


def test_a_pose_recorded_with_another_scheme(run_cli, tmp_path):
    from core.patterns import two_shot_patterns

    cap = tmp_path / "cap"
    cap.mkdir()
    Board("checkerboard", 7, 10, 12.0).save(cap / "board.yaml")
    for i in range(5):
        with DumpWriter(cap / f"pose_{i:03d}", two_shot_patterns((64, 48))) as w:
            w.add(np.zeros((48, 64, 3), np.uint8), 0, 0, 0)
            w.add(np.zeros((48, 64, 3), np.uint8), 1, 1, 1)
    err = one_line_error(run_cli("calibrate", "--from", cap, "--out", tmp_path / "c.yaml"))
    assert "pose_000: scheme is 'two-shot'" in err


def test_too_few_poses(run_cli, tmp_path):
    cap = tmp_path / "cap"
    cap.mkdir()
    Board("checkerboard", 7, 10, 12.0).save(cap / "board.yaml")
    pats = graycode_patterns((64, 48))
    for i in range(3):
        with DumpWriter(cap / f"pose_{i:03d}", pats) as w:
            for p in range(len(pats)):
                w.add(np.zeros((48, 64, 3), np.uint8), p, p, p)
    err = one_line_error(run_cli("calibrate", "--from", cap, "--out", tmp_path / "c.yaml"))
    assert "too few poses: 3 (minimum 5" in err
    assert not (tmp_path / "c.yaml").exists()


def test_bad_arguments(run_cli, tmp_path):
    err = one_line_error(run_cli("calibrate", "--auto", "--poses", "0", "--out", tmp_path / "c.yaml"))
    assert "--poses" in err and "must be greater than 0" in err
    err = one_line_error(run_cli("calibrate", "--auto", "--out", tmp_path / "missing" / "c.yaml"))
    assert "does not exist" in err
    err = one_line_error(
        run_cli("calibrate", "--auto", "--scene", "plane", "--poses", "3", "--out", tmp_path / "c.yaml")
    )
    assert "no calibration board" in err


# ----------------------------------------------------------------------------- the full solve (slow)


@pytest.fixture(scope="module")
def auto_run(run_cli_module, tmp_path_factory):
    """`slscan calibrate --auto --poses 8` once (the bench runs 15): its output, file and capture."""
    d = tmp_path_factory.mktemp("auto")
    proc = run_cli_module("calibrate", "--auto", "--poses", "8", "--out", d / "cal.yaml", timeout=900)
    return proc, d


@pytest.fixture(scope="module")
def run_cli_module():
    import subprocess
    import sys

    def run(*args, timeout=300):
        return subprocess.run(
            [sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True, timeout=timeout
        )

    return run


@pytest.mark.slow
def test_auto_recovers_the_true_calibration(auto_run):
    from calibration.auto import make_rig

    proc, d = auto_run
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "verdict: good" in proc.stdout
    cal = Calibration.load(d / "cal.yaml")
    truth = make_rig("checkerboard").calibration
    err = compare(cal, truth)
    for key, limit in TARGETS.items():
        assert err[key] <= limit, (key, err[key], proc.stdout)
    assert cal.rms["camera_rms"] <= 0.2 and cal.rms["projector_rms"] <= 0.3
    assert np.abs(cal.color_mixing - truth.color_mixing).max() < 0.01
    assert (d / "cal.capture" / "board.yaml").is_file() and (d / "cal.capture" / "pose_007" / "dump.yaml").is_file()


@pytest.mark.slow
def test_from_repeats_the_solve_and_survives_bad_poses(auto_run, run_cli_module, tmp_path):
    _, d = auto_run
    cap = tmp_path / "cap"
    shutil.copytree(d / "cal.capture", cap)
    # pose_008: the board left the view; pose_009: the projector never switched (all frames white)
    pats = graycode_patterns((1024, 768))
    white = read_dump(cap / "pose_000").load_frame(0)  # pattern 0 is all-white
    with DumpWriter(cap / "pose_008", pats) as w:
        for p in range(len(pats)):
            w.add(np.full_like(white, 40), p, p, p)
    with DumpWriter(cap / "pose_009", pats) as w:
        for p in range(len(pats)):
            w.add(white, p, p, p)
    out = tmp_path / "again.yaml"
    proc2 = run_cli_module("calibrate", "--from", cap, "--out", out)
    assert proc2.returncode == 0, proc2.stdout + proc2.stderr
    assert "pose_008: skipped: no board found" in proc2.stdout
    assert "pose_009: skipped: Gray code undecodable on the board" in proc2.stdout
    a, b = Calibration.load(d / "cal.yaml"), Calibration.load(out)
    # the same solve up to OpenCV's floating-point reduction order (threads)
    assert np.abs(a.camera_matrix - b.camera_matrix).max() < 0.05 and np.abs(a.T - b.T).max() < 0.01
    assert np.abs(a.projector_matrix - b.projector_matrix).max() < 0.05
    # without --force an existing capture is never overwritten by --auto
    proc3 = run_cli_module("calibrate", "--auto", "--poses", "5", "--capture", cap, "--out", tmp_path / "x.yaml")
    assert "already exists" in one_line_error(proc3)


def test_file_written_only_when_the_solve_passes_or_with_force(tmp_path, monkeypatch, capsys):
    """The write gate of `calibrate --from`, on a real solve of synthetic correspondences."""
    from app.cli import main
    from calibration import session
    from calibration.poses import plan_poses
    from calibration.solve import solve
    from drivers.sim.optics import Geometry

    truth = Geometry().calibration()
    board = Board("checkerboard", 7, 10, 12.0)
    obj = board.object_points().astype(np.float64)
    obs = []
    rng = np.random.default_rng(0)
    for i, (rvec, tvec) in enumerate(plan_poses(board, truth, 8, seed=1)):
        R, _ = cv2.Rodrigues(rvec)
        X = obj @ R.T + tvec
        c, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), truth.camera_matrix, truth.camera_distortion)
        rp, _ = cv2.Rodrigues(truth.R)
        p, _ = cv2.projectPoints(X, rp, truth.T, truth.projector_matrix, truth.projector_distortion)
        noise = rng.normal(0, 0.05, (2, len(obj), 2))
        obs.append(
            session.PoseObservation(f"pose_{i:03d}", obj, c.reshape(-1, 2) + noise[0], p.reshape(-1, 2) + noise[1])
        )
    cap = tmp_path / "cap"
    cap.mkdir()
    board.save(cap / "board.yaml")
    for i in range(8):
        (cap / f"pose_{i:03d}").mkdir()
        (cap / f"pose_{i:03d}" / "dump.yaml").write_text("format: slscan-dump\n")

    def fake_solve_capture(capture, camera_gamma=None, progress=None, fail=False):
        sol = solve(obs, truth.camera_size, truth.projector_size)
        if fail:
            sol.problems.append("camera RMS 0.071 px is above 0.01 px")
        return session.CaptureResult(sol, None, truth)

    monkeypatch.setattr(session, "solve_capture", fake_solve_capture)
    out = tmp_path / "good.yaml"
    assert main(["calibrate", "--from", str(cap), "--out", str(out)]) == 0
    assert Calibration.load(out).rms["camera_rms"] < 0.1
    assert "verdict: good" in capsys.readouterr().out

    monkeypatch.setattr(session, "solve_capture", lambda *a, **k: fake_solve_capture(*a, **k, fail=True))
    bad = tmp_path / "bad.yaml"
    assert main(["calibrate", "--from", str(cap), "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "not written" in err and "--force" in err and not bad.exists()
    assert main(["calibrate", "--from", str(cap), "--out", str(bad), "--force"]) == 0
    assert bad.exists() and "written with --force" in capsys.readouterr().err
