"""The solver on exact synthetic correspondences: truth recovered, bad views and bad pose sets refused."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.board import Board
from calibration.poses import plan_poses
from calibration.solve import MIN_POSES, PoseObservation, solve
from calibration.validate import compare
from drivers.sim.optics import Geometry

BOARD = Board("checkerboard", 7, 10, 12.0)
TRUTH = Geometry().calibration()


def observe(poses, cam_noise=0.03, proj_noise=0.03, seed=0) -> list[PoseObservation]:
    rng = np.random.default_rng(seed)
    obj = BOARD.object_points().astype(np.float64)
    rp, _ = cv2.Rodrigues(TRUTH.R)
    out = []
    for i, (rvec, tvec) in enumerate(poses):
        R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
        X = obj @ R.T + tvec
        c, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), TRUTH.camera_matrix, TRUTH.camera_distortion)
        p, _ = cv2.projectPoints(X, rp, TRUTH.T, TRUTH.projector_matrix, TRUTH.projector_distortion)
        out.append(
            PoseObservation(
                f"pose_{i:03d}",
                obj.astype(np.float32),
                (c.reshape(-1, 2) + rng.normal(0, cam_noise, (len(obj), 2))).astype(np.float32),
                (p.reshape(-1, 2) + rng.normal(0, proj_noise, (len(obj), 2))).astype(np.float32),
            )
        )
    return out


def test_recovers_the_truth():
    sol = solve(observe(plan_poses(BOARD, TRUTH, 15, seed=1)), TRUTH.camera_size, TRUTH.projector_size)
    assert sol.passed, sol.problems
    err = compare(sol.calibration, TRUTH)
    assert err["camera_focal_error_pct"] < 0.3 and err["projector_focal_error_pct"] < 0.3
    assert err["camera_principal_error_px"] < 3 and err["projector_principal_error_px"] < 3
    assert err["baseline_error_mm"] < 0.5 and err["rotation_error_deg"] < 0.1
    assert sol.calibration.rms["camera_rms"] == pytest.approx(0.03 * np.sqrt(2), rel=0.25)
    assert all(v.used for v in sol.views)


def test_outlier_view_is_rejected_with_a_reason():
    obs = observe(plan_poses(BOARD, TRUTH, 12, seed=2))
    obs[4].projector_points = obs[4].projector_points + np.random.default_rng(0).normal(0, 2.0, (70, 2)).astype(
        np.float32
    )
    sol = solve(obs, TRUTH.camera_size, TRUTH.projector_size)
    bad = [v for v in sol.views if not v.used]
    assert [v.name for v in bad] == ["pose_004"]
    assert "projector reprojection error" in bad[0].reason and "median" in bad[0].reason
    assert sol.passed
    assert compare(sol.calibration, TRUTH)["rotation_error_deg"] < 0.1


def test_too_few_poses():
    sol = solve(observe(plan_poses(BOARD, TRUTH, MIN_POSES - 1, seed=3)), TRUTH.camera_size, TRUTH.projector_size)
    assert not sol.passed and sol.calibration is None
    assert "too few usable poses: 4 (minimum 5" in sol.problems[0]


def _fronto(n: int, tilt_deg: float = 0.0, axis: str = "both"):
    pts = BOARD.object_points()
    centre = (pts.min(0) + pts.max(0)) / 2
    poses = []
    for i in range(n):
        a = np.deg2rad(tilt_deg) * (1 if i % 2 else -1)
        rvec = {"both": np.array([a, 0, 0]) if i % 4 < 2 else np.array([0, a, 0]), "x": np.array([a, 0, 0])}[axis]
        R, _ = cv2.Rodrigues(rvec)
        shift = np.array([(i % 3 - 1) * 15.0, (i % 2) * 10.0, 780.0 + 20 * (i % 3)])
        poses.append((rvec, shift - R @ centre))
    return poses


def test_all_fronto_parallel_poses_are_refused():
    sol = solve(observe(_fronto(10, 2.0)), TRUTH.camera_size, TRUTH.projector_size)
    assert sol.calibration is None
    assert "degenerate poses" in sol.problems[0] and "fronto-parallel" in sol.problems[0]


def test_tilts_about_one_axis_only_are_refused():
    sol = solve(observe(_fronto(10, 25.0, axis="x")), TRUTH.camera_size, TRUTH.projector_size)
    assert sol.calibration is None
    assert "same way" in sol.problems[0]


def test_a_pose_with_too_few_corners_is_skipped_not_fatal():
    obs = observe(plan_poses(BOARD, TRUTH, 8, seed=4))
    for attr in ("object_points", "camera_points", "projector_points"):
        setattr(obs[2], attr, getattr(obs[2], attr)[:5])
    sol = solve(obs, TRUTH.camera_size, TRUTH.projector_size)
    assert sol.passed
    assert "only 5 corners" in next(v.reason for v in sol.views if v.name == "pose_002")
