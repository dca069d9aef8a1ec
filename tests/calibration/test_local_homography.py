"""Corner -> projector mapping by local homographies, against exact and ground-truth projector coordinates."""

from __future__ import annotations

import cv2
import numpy as np

from calibration.auto import rig_board
from calibration.board import detect
from calibration.local_homography import corners_to_projector, fit_homography
from calibration.poses import plan_poses


def true_projector_corners(board, cal, rvec, tvec) -> np.ndarray:
    """Projector pixels of the board's true 3D corners, through the true calibration."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    X = board.object_points().astype(np.float64) @ R.T + tvec
    rp, _ = cv2.Rodrigues(cal.R)
    uv, _ = cv2.projectPoints(X, rp, cal.T, cal.projector_matrix, cal.projector_distortion)
    return uv.reshape(-1, 2)


def _maps_from_homography(H: np.ndarray, shape=(120, 160)):
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    q = np.stack([xs, ys, np.ones_like(xs)], -1) @ H.T
    return q[..., 0] / q[..., 2], q[..., 1] / q[..., 2]


H_TRUE = np.array([[1.9, 0.12, 40.0], [-0.05, 1.7, 25.0], [1e-4, -2e-4, 1.0]])


def test_fit_is_exact_on_a_homography():
    rng = np.random.default_rng(1)
    src = rng.uniform(0, 100, (50, 2))
    q = np.c_[src, np.ones(50)] @ H_TRUE.T
    H = fit_homography(src, q[:, :2] / q[:, 2:])
    assert np.allclose(H, H_TRUE, rtol=1e-8, atol=1e-10)


def test_corners_exact_and_robust_to_decoding_errors():
    col, row = _maps_from_homography(H_TRUE)
    valid = np.ones(col.shape, bool)
    corners = np.array([[40.3, 50.7], [80.5, 60.25], [120.9, 90.1]])
    q = np.c_[corners, np.ones(3)] @ H_TRUE.T
    expected = q[:, :2] / q[:, 2:]
    out, ok = corners_to_projector(corners, col, row, valid, half=10)
    assert ok.all() and np.abs(out - expected).max() < 1e-6
    # 5 % of the pixels decoded wrongly by whole stripes (as at square edges): still exact
    rng = np.random.default_rng(2)
    bad = rng.random(col.shape) < 0.05
    col_bad = col + bad * rng.choice([-16.0, 8.0, 32.0], col.shape)
    out, ok = corners_to_projector(corners, col_bad, row, valid, half=10)
    assert ok.all() and np.abs(out - expected).max() < 1e-6
    # half the decoded pixels missing (black squares): still exact
    sparse = valid & (rng.random(col.shape) < 0.5)
    out, ok = corners_to_projector(corners, col, row, sparse, half=10)
    assert ok.all() and np.abs(out - expected).max() < 1e-6


def test_corner_without_enough_decoded_pixels_is_not_guessed():
    col, row = _maps_from_homography(H_TRUE)
    valid = np.ones(col.shape, bool)
    valid[30:70, 20:60] = False
    out, ok = corners_to_projector(np.array([[40.0, 50.0], [100.0, 60.0]]), col, row, valid, half=10)
    assert ok.tolist() == [False, True] and np.isnan(out[0]).all()


def test_rig_ground_truth_maps_give_true_projector_corners(board_rig):
    """On the virtual rig (lens distortion, tilted board) with its true projector maps:
    the corner's projector position agrees with projecting the true 3D corner (< 0.05 px)."""
    rig = board_rig("checkerboard")
    board = rig_board(rig)
    truth = rig.calibration
    white = rig.prepare(np.full((rig.projector_size[1], rig.projector_size[0], 3), 255, np.uint8))
    worst = 0.0
    for rvec, tvec in plan_poses(board, truth, 2, seed=5):
        rig.set_board_pose(rvec, tvec)
        det = detect(board, rig.render(white))
        gt = rig.ground_truth
        proj, ok = corners_to_projector(det.corners, gt.column, gt.row, gt.lit & np.isfinite(gt.column))
        assert ok.all()
        expected = true_projector_corners(board, truth, rvec, tvec)[det.ids]
        # the detected camera corner is off by its detection error (~0.03 px): compare like with like
        true_cam = rig.board_corners_image()[det.ids]
        proj_at_true, _ = corners_to_projector(true_cam, gt.column, gt.row, gt.lit & np.isfinite(gt.column))
        worst = max(worst, float(np.abs(proj_at_true - expected).max()))
        assert np.sqrt(((proj - expected) ** 2).sum(1).mean()) < 0.15
    assert worst < 0.05
