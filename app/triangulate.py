"""Triangulation: camera pixel + projector column -> depth, with per-pixel geometry precomputed.

With lens distortion a projector "column" is a curved surface, not a plane, so instead of column
planes we precompute, once per calibration and depth range, for every camera pixel the projector
column u seen at K inverse depths w = 1/Z spread over the working range (its camera ray is
undistorted, each point projected through the projector model with its distortion). Along a ray
u(w) is a smooth monotone function (a Moebius map without distortion, nearly linear in w), so
the per-frame path only finds the node interval and interpolates linearly in w; K is raised
until the interpolation error at the interval midpoints is below `max_error_px`. The same table
gives each pixel's allowed column interval, which picks between repeated copies of a stripe
sequence and masks everything outside the depth range.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from app.errors import InputError
from calibration.model import Calibration


@njit(cache=True, nogil=True)
def _depth_from_column(column, nodes, w0, dw, depth):
    H, W, K = nodes.shape
    for y in range(H):
        for x in range(W):
            u = column[y, x]
            depth[y, x] = 0.0
            if not (u == u):  # NaN
                continue
            n0 = nodes[y, x, 0]
            n1 = nodes[y, x, K - 1]
            if not (n0 == n0):
                continue
            inc = n1 > n0
            if (inc and (u < n0 or u > n1)) or ((not inc) and (u > n0 or u < n1)):
                continue  # outside the depth range
            # initial guess assuming linear u(w), then walk to the bracketing interval
            i = int((u - n0) / (n1 - n0) * (K - 1))
            if i < 0:
                i = 0
            if i > K - 2:
                i = K - 2
            if inc:
                while i > 0 and u < nodes[y, x, i]:
                    i -= 1
                while i < K - 2 and u > nodes[y, x, i + 1]:
                    i += 1
            else:
                while i > 0 and u > nodes[y, x, i]:
                    i -= 1
                while i < K - 2 and u < nodes[y, x, i + 1]:
                    i += 1
            a = nodes[y, x, i]
            b = nodes[y, x, i + 1]
            t = (u - a) / (b - a) if b != a else 0.0
            depth[y, x] = 1.0 / (w0 + (i + t) * dw)


@dataclass
class PointCloud:
    xyz: np.ndarray  # (N, 3) float32 mm, camera coordinates
    rgb: np.ndarray  # (N, 3) uint8


class Triangulator:
    """Per-calibration precomputation; `depth(column)` is the per-frame path."""

    def __init__(
        self,
        calibration: Calibration,
        depth_range_mm: tuple[float, float] = (100.0, 5000.0),
        max_error_px: float = 0.01,
        max_nodes: int = 33,
    ) -> None:
        near, far = float(depth_range_mm[0]), float(depth_range_mm[1])
        if not 0 < near < far:
            raise InputError(f"depth range {depth_range_mm} must be [near, far] with 0 < near < far")
        self.calibration = calibration
        self.depth_range_mm = (near, far)
        w, h = calibration.camera_size
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
        pts = np.stack([xs.ravel(), ys.ravel()], axis=1).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
        und = cv2.undistortPoints(pts, calibration.camera_matrix, calibration.camera_distortion, None, None, None, crit)
        self.ray = und.reshape(h, w, 2).astype(np.float32)  # normalised (x/z, y/z) per pixel
        self.w0 = 1.0 / near
        K = 9
        while True:
            self.dw = (1.0 / far - 1.0 / near) / (K - 1)
            nodes = np.empty((h, w, K), np.float32)
            for i in range(K):
                nodes[:, :, i] = self._project_u(self.ray, self.w0 + i * self.dw)
            err = self._midpoint_error(nodes, K)
            if err <= max_error_px or K >= max_nodes:
                break
            K = 2 * K - 1
        self.nodes = nodes
        self.interp_error_px = err
        inc = nodes[:, :, -1] > nodes[:, :, 0]
        steps = np.diff(nodes, axis=2)
        monotone = np.where(inc, (steps > 0).all(axis=2), (steps < 0).all(axis=2))
        self.nodes[~monotone] = np.nan  # rays along which the projector column is not monotone
        self.column_lo = np.minimum(nodes[:, :, 0], nodes[:, :, -1]).astype(np.float32)
        self.column_hi = np.maximum(nodes[:, :, 0], nodes[:, :, -1]).astype(np.float32)

    def _project_u(self, ray: np.ndarray, w: float) -> np.ndarray:
        """Distorted projector column of the points at inverse depth w on the given camera rays."""
        cal = self.calibration
        r = ray.astype(np.float64)
        Rm = cal.R
        z = 1.0 / w
        # X_p = R (z * (x, y, 1)) + T
        X = z * (Rm[0, 0] * r[..., 0] + Rm[0, 1] * r[..., 1] + Rm[0, 2]) + cal.T[0]
        Y = z * (Rm[1, 0] * r[..., 0] + Rm[1, 1] * r[..., 1] + Rm[1, 2]) + cal.T[1]
        Z = z * (Rm[2, 0] * r[..., 0] + Rm[2, 1] * r[..., 1] + Rm[2, 2]) + cal.T[2]
        x = X / Z
        y = Y / Z
        k1, k2, p1, p2, k3 = cal.projector_distortion
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        K = cal.projector_matrix
        return K[0, 0] * xd + K[0, 1] * yd + K[0, 2]

    def _midpoint_error(self, nodes: np.ndarray, K: int) -> float:
        sub = self.ray[::8, ::8]
        worst = 0.0
        for i in range(K - 1):
            true = self._project_u(sub, self.w0 + (i + 0.5) * self.dw)
            interp = 0.5 * (nodes[::8, ::8, i] + nodes[::8, ::8, i + 1])
            worst = max(worst, float(np.nanmax(np.abs(true - interp))))
        return worst

    @property
    def column_range(self) -> tuple[np.ndarray, np.ndarray]:
        """Per pixel, the projector columns that fall inside the depth range."""
        return self.column_lo, self.column_hi

    def check_size(self, width: int, height: int, where: str) -> None:
        self.calibration.check_camera_size(width, height, where)

    def depth(self, column: np.ndarray) -> np.ndarray:
        """Depth Z in mm (float32, 0 = none) from a projector column map (NaN = none)."""
        h, w = self.ray.shape[:2]
        if column.shape != (h, w):
            raise InputError(f"column map is {column.shape[1]}x{column.shape[0]}, calibration camera is {w}x{h}")
        out = np.empty((h, w), np.float32)
        _depth_from_column(np.ascontiguousarray(column, np.float32), self.nodes, self.w0, self.dw, out)
        return out

    def points(self, depth: np.ndarray, image: np.ndarray | None = None) -> PointCloud:
        """Camera-frame 3D points (mm) of the pixels with depth, coloured from `image` (RGB)."""
        m = depth > 0
        z = depth[m]
        xyz = np.empty((z.size, 3), np.float32)
        xyz[:, 0] = self.ray[..., 0][m] * z
        xyz[:, 1] = self.ray[..., 1][m] * z
        xyz[:, 2] = z
        if image is None:
            rgb = np.full((z.size, 3), 255, np.uint8)
        else:
            img = image if image.dtype == np.uint8 else (image >> 8).astype(np.uint8)
            rgb = np.ascontiguousarray(img[m])
        return PointCloud(xyz, rgb)
