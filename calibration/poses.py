"""Board poses with tilt variety, for the virtual rig's `--auto` capture and the wizard's hints.

A good calibration set tilts the board 20–40° about both image axes (the focal length is only
observable through perspective), keeps it fully inside both the camera and the projector fields,
and spreads it over the camera field. Pure: the calibration in, (rvec, tvec) board->camera out.
"""

from __future__ import annotations

import cv2
import numpy as np

from calibration.board import Board
from core.calibration import Calibration


def _look(tilt_x_deg: float, tilt_y_deg: float, roll_deg: float) -> np.ndarray:
    rx, _ = cv2.Rodrigues(np.array([np.deg2rad(tilt_x_deg), 0.0, 0.0]))
    ry, _ = cv2.Rodrigues(np.array([0.0, np.deg2rad(tilt_y_deg), 0.0]))
    rz, _ = cv2.Rodrigues(np.array([0.0, 0.0, np.deg2rad(roll_deg)]))
    return ry @ rx @ rz


def _project(X: np.ndarray, K: np.ndarray, D: np.ndarray, R: np.ndarray, T: np.ndarray) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(R)
    uv, _ = cv2.projectPoints(X.reshape(-1, 1, 3).astype(np.float64), rvec, T.reshape(3, 1), K, D)
    return uv.reshape(-1, 2)


def board_outline(board: Board, margin_mm: float | None = None) -> np.ndarray:
    """The corners of the printed area (4, 3), board frame, a square beyond the outer corners."""
    pts = board.object_points()
    m = board.square_mm if margin_mm is None else margin_mm
    x0, y0 = pts[:, 0].min() - m, pts[:, 1].min() - m
    x1, y1 = pts[:, 0].max() + m, pts[:, 1].max() + m
    return np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], np.float64)


def visible(board: Board, cal: Calibration, rvec: np.ndarray, tvec: np.ndarray, margin_px: float = 12.0) -> bool:
    """Whole printed board inside the camera and the projector image, facing both."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    t = np.asarray(tvec, np.float64).reshape(3)
    X = board_outline(board) @ R.T + t
    if np.any(X[:, 2] <= 0):
        return False
    n = R[:, 2]
    centre = X.mean(axis=0)
    proj_centre = cal.projector_center_in_camera
    if np.dot(n, centre) * np.dot(n, centre - proj_centre) <= 0:
        return False  # camera and projector on different sides of the board
    for K, D, Rv, Tv, (w, h) in (
        (cal.camera_matrix, cal.camera_distortion, np.eye(3), np.zeros(3), cal.camera_size),
        (cal.projector_matrix, cal.projector_distortion, cal.R, cal.T, cal.projector_size),
    ):
        Xv = X @ Rv.T + Tv
        if np.any(Xv[:, 2] <= 0):
            return False
        uv = _project(X, K, D, Rv, Tv)
        if np.any(uv < margin_px) or np.any(uv[:, 0] > w - 1 - margin_px) or np.any(uv[:, 1] > h - 1 - margin_px):
            return False
    return True


def plan_poses(
    board: Board, cal: Calibration, n: int, seed: int = 0, fill: float = 0.8, max_tilt_deg: float = 40.0
) -> list[tuple[np.ndarray, np.ndarray]]:
    """n poses (rvec, tvec) board->camera, tilted in turn about both axes, spread over the field.

    The distance makes the board fill about `fill` of the camera width; tilts cycle through eight
    directions with magnitudes 15..max_tilt_deg, and the board centre wanders over the field. A
    candidate that leaves either field is shrunk towards the centre and the tilt reduced.
    """
    rng = np.random.default_rng(seed)
    pts = board.object_points().astype(np.float64)
    centre_b = (pts.min(axis=0) + pts.max(axis=0)) / 2
    width_mm = float(np.ptp(pts[:, 0]) + 2 * board.square_mm)
    fx = cal.camera_matrix[0, 0]
    z0 = fx * width_mm / (fill * cal.camera_size[0])
    K = cal.camera_matrix
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    directions = np.deg2rad(np.arange(8) * 45.0 + 22.5)
    attempts = 0
    while len(poses) < n:
        i = len(poses)
        attempts += 1
        if attempts > 200 * n:
            raise RuntimeError("cannot place the board inside both fields; check the rig geometry")
        a = directions[i % 8] + rng.uniform(-0.2, 0.2)
        mag = rng.uniform(15.0, max_tilt_deg) if i % 4 else rng.uniform(5.0, 15.0)
        shrink = 0.85 ** min(attempts // 20, 10)
        tilt_x, tilt_y = mag * shrink * np.sin(a), mag * shrink * np.cos(a)
        roll = rng.uniform(-15, 15)
        R = _look(tilt_x, tilt_y, roll)
        z = z0 * rng.uniform(0.9, 1.15)
        # Wander the centre over the camera field (normalised image offset up to ~25 %).
        off = rng.uniform(-0.25, 0.25, 2) * shrink * np.array(cal.camera_size)
        ray = np.array([(K[0, 2] + off[0] - K[0, 2]) / K[0, 0], (K[1, 2] + off[1] - K[1, 2]) / K[1, 1], 1.0])
        centre_c = ray * z
        t = centre_c - R @ centre_b
        rvec, _ = cv2.Rodrigues(R)
        if visible(board, cal, rvec, t):
            poses.append((rvec.ravel(), t))
            attempts = 0
    return poses
