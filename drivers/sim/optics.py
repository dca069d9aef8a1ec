"""Pinhole-with-distortion models of the virtual camera and projector, and the rig's true geometry.

OpenCV conventions: (k1 k2 p1 p2 k3) distortion, pixel centres at integer coordinates, mm,
X_projector = R · X_camera + T. The default geometry puts the projector 200 mm to the right
of the camera, converging on the middle of the working volume (~720 mm), with a camera focal
length twice the projector's, so that a 1-pixel projector stripe is ~2 camera pixels wide at
640x480 (as in the paper's set-up).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from core.calibration import Calibration
from core.errors import InputError
from drivers.sim.kernels import affine3


@dataclass(frozen=True)
class Geometry:
    """Everything that fixes the rig's true calibration (all plain numbers, YAML-overridable)."""

    camera_size: tuple[int, int] = (640, 480)
    camera_focal_px: float = 2200.0  # at 640 px width; scaled with the width for other sizes
    camera_principal_offset_px: tuple[float, float] = (2.9, -3.4)  # from the image centre, at 640 px
    camera_distortion: tuple[float, ...] = (-0.11, 0.21, 0.0004, -0.0003, 0.0)
    projector_size: tuple[int, int] = (1024, 768)
    projector_focal_px: float = 1100.0  # at 1024 px width
    projector_principal_offset_px: tuple[float, float] = (-4.0, 36.0)  # projectors throw slightly upward
    projector_distortion: tuple[float, ...] = (0.035, -0.05, 0.0, 0.0, 0.0)
    projector_position_mm: tuple[float, float, float] = (200.0, -12.0, 6.0)  # in camera coordinates
    projector_target_mm: tuple[float, float, float] = (0.0, 0.0, 720.0)  # where its optical axis points
    projector_roll_deg: float = 0.4

    def camera_matrix(self) -> np.ndarray:
        w, h = self.camera_size
        s = w / 640.0
        f = self.camera_focal_px * s
        ox, oy = self.camera_principal_offset_px
        return np.array([[f, 0, (w - 1) / 2 + ox * s], [0, f, (h - 1) / 2 + oy * s], [0, 0, 1]])

    def projector_matrix(self) -> np.ndarray:
        w, h = self.projector_size
        s = w / 1024.0
        f = self.projector_focal_px * s
        ox, oy = self.projector_principal_offset_px
        return np.array([[f, 0, (w - 1) / 2 + ox * s], [0, f, (h - 1) / 2 + oy * s], [0, 0, 1]])

    def extrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """R, T with X_projector = R X_camera + T: a look-at from the projector position."""
        C = np.asarray(self.projector_position_mm, np.float64)
        z = np.asarray(self.projector_target_mm, np.float64) - C
        z /= np.linalg.norm(z)
        x = np.cross([0.0, 1.0, 0.0], z)  # camera y is down; keep the projector's y down too
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])
        roll, _ = cv2.Rodrigues(np.array([0.0, 0.0, np.deg2rad(self.projector_roll_deg)]))
        R = roll @ R
        return R, -R @ C

    def calibration(self, color_mixing: np.ndarray | None = None) -> Calibration:
        R, T = self.extrinsics()
        return Calibration(
            camera_size=self.camera_size,
            camera_matrix=self.camera_matrix(),
            camera_distortion=np.asarray(self.camera_distortion, np.float64),
            projector_size=self.projector_size,
            projector_matrix=self.projector_matrix(),
            projector_distortion=np.asarray(self.projector_distortion, np.float64),
            R=R,
            T=T,
            rms={"camera_rms": 0.0, "projector_rms": 0.0, "stereo_rms": 0.0},
            color_mixing=color_mixing,
        )

    def check(self, where: str) -> None:
        """Refuse set-ups no rig can have; the message names the field."""
        for key in ("camera_size", "projector_size"):
            w, h = getattr(self, key)
            if not (isinstance(w, int) and isinstance(h, int) and 16 <= w <= 8192 and 16 <= h <= 8192):
                raise InputError(f"{where}: '{key}' must be [w, h] with whole numbers from 16 to 8192, found {[w, h]}")
        for key in ("camera_focal_px", "projector_focal_px"):
            if not float(getattr(self, key)) > 0:
                raise InputError(f"{where}: '{key}' must be > 0, found {getattr(self, key)}")
        for key in ("camera_distortion", "projector_distortion"):
            d = getattr(self, key)
            if len(d) != 5 or not np.all(np.isfinite(d)) or np.max(np.abs(d)) > 2:
                raise InputError(f"{where}: '{key}' must be 5 finite coefficients (k1 k2 p1 p2 k3), |k| <= 2")
        C = np.asarray(self.projector_position_mm, np.float64)
        if np.linalg.norm(C) < 1.0:
            raise InputError(f"{where}: 'projector_position_mm' is at the camera centre: no baseline to triangulate")
        target = np.asarray(self.projector_target_mm, np.float64)
        if target[2] <= 0:
            raise InputError(f"{where}: 'projector_target_mm' is behind the camera (z must be > 0)")
        if np.linalg.norm(target - C) < 1.0:
            raise InputError(f"{where}: 'projector_target_mm' equals 'projector_position_mm'")
        z = (target - C) / np.linalg.norm(target - C)
        if abs(z[1]) > 0.999:
            raise InputError(f"{where}: the projector points straight up or down; aim it at the scene")


_RAY_CACHE: dict[bytes, np.ndarray] = {}


def camera_rays(K: np.ndarray, dist: np.ndarray, size: tuple[int, int], step: float = 1.0) -> np.ndarray:
    """Unit ray directions (h, w, 3) through camera pixel centres (undistorted, camera frame).

    `step` < 1 samples a finer grid (sub-pixel positions). Cached: rigs with the same camera share them.
    """
    key = np.concatenate([np.ravel(K), np.ravel(dist), [size[0], size[1], step]]).tobytes()
    if key not in _RAY_CACHE:
        if len(_RAY_CACHE) > 4:
            _RAY_CACHE.clear()
        rays = _camera_rays(K, dist, size, step)
        rays.flags.writeable = False
        _RAY_CACHE[key] = rays
    return _RAY_CACHE[key]


def _camera_rays(K: np.ndarray, dist: np.ndarray, size: tuple[int, int], step: float) -> np.ndarray:
    w, h = size
    xs = np.arange(0, w, step, dtype=np.float64)
    ys = np.arange(0, h, step, dtype=np.float64)
    u, v = np.meshgrid(xs, ys)
    pts = np.stack([u.ravel(), v.ravel()], axis=1)
    xy = undistort_normalized(pts, K, dist)
    d = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d.reshape(len(ys), len(xs), 3)


def distort_normalized(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """OpenCV's (k1 k2 p1 p2 k3) model applied to normalized coordinates (N, 2)."""
    k1, k2, p1, p2, k3 = dist
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=1)


def undistort_normalized(pix: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Normalized undistorted coordinates (N, 2) of pixel positions (N, 2): Newton on the model.

    Exact to ~1e-12 (cv2.undistortPoints' fixed iteration count leaves ~1e-4 px errors).
    """
    target = np.stack([(pix[:, 0] - K[0, 2]) / K[0, 0], (pix[:, 1] - K[1, 2]) / K[1, 1]], axis=1)
    xy = target.copy()
    e = 1e-7
    ex, ey = np.array([e, 0.0]), np.array([0.0, e])
    for _ in range(30):
        f = distort_normalized(xy, dist) - target
        if np.max(np.abs(f)) < 1e-13:
            break
        fx = (distort_normalized(xy + ex, dist) - distort_normalized(xy - ex, dist)) / (2 * e)
        fy = (distort_normalized(xy + ey, dist) - distort_normalized(xy - ey, dist)) / (2 * e)
        det = fx[:, 0] * fy[:, 1] - fy[:, 0] * fx[:, 1]
        step_x = (fy[:, 1] * f[:, 0] - fy[:, 0] * f[:, 1]) / det
        step_y = (fx[:, 0] * f[:, 1] - fx[:, 1] * f[:, 0]) / det
        xy = xy - np.stack([step_x, step_y], axis=1)
    return xy


def project(X: np.ndarray, K: np.ndarray, dist: np.ndarray, R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Pixel coordinates (N, 2) of camera-frame points X (N, 3) in a view with pose (R, T).

    The same model as cv2.projectPoints (tests check they agree), several times faster.
    """
    Xv = affine3(X, np.asarray(R, np.float64).T, after=np.asarray(T, np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = Xv[:, :2] / Xv[:, 2:3]
    xd = distort_normalized(xy, np.asarray(dist, np.float64).ravel())
    return np.stack([K[0, 0] * xd[:, 0] + K[0, 1] * xd[:, 1] + K[0, 2], K[1, 1] * xd[:, 1] + K[1, 2]], axis=1)
