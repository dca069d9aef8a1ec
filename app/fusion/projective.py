"""Point-to-plane ICP with projective correspondences (as KinectFusion's), compiled with numba.

The map's points near the scan are drawn once per scan into a coarse image of the predicted camera (`model_view`:
one pixel per `cell_px` camera pixels, the nearest point facing the camera wins each pixel). Each iteration then
moves every scan point by the current estimate, projects it into that image and takes the map point drawn there as
its correspondence, or in the fine stage the nearest of the map points drawn in the 3 x 3 pixels around it (O(1)
per point: no search tree); the step is the Tukey-weighted point-to-plane Gauss-Newton
step on the map's normals, as Open3D's TransformationEstimationPointToPlane with TukeyLoss. `evaluate` gives the
fitness and inlier RMSE the failure test reads, with the nearest map point among the 3 x 3 drawn pixels around
each scan point's (close to a true nearest neighbour: the map holds one point per 1 mm cell and a drawn pixel
covers ~1 mm at the working distance).

Why: Open3D's legacy ICP builds a k-d tree of the map per call and searches it for every point and iteration
(~1.7 ms an iteration for 4,000 points here); this does an iteration in a fraction of a millisecond, with the same
poses against the rig's truth (docs/performance.md, "Whole models").
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)


@njit(cache=True, nogil=True)
def model_view(tp, tn, M0, fx, fy, cx, cy, W, H):
    """The map points (model frame) in the camera at pose M0 (camera -> model): (grid (W*H) of point indices or
    -1, their positions V and normals N in that camera's frame). Back-facing points are not drawn."""
    n = tp.shape[0]
    grid = np.full(W * H, -1, np.int64)
    zbuf = np.full(W * H, np.inf)
    V = np.empty((n, 3))
    N = np.empty((n, 3))
    for i in range(n):
        a0 = tp[i, 0] - M0[0, 3]
        a1 = tp[i, 1] - M0[1, 3]
        a2 = tp[i, 2] - M0[2, 3]
        x = M0[0, 0] * a0 + M0[1, 0] * a1 + M0[2, 0] * a2
        y = M0[0, 1] * a0 + M0[1, 1] * a1 + M0[2, 1] * a2
        z = M0[0, 2] * a0 + M0[1, 2] * a1 + M0[2, 2] * a2
        nx = M0[0, 0] * tn[i, 0] + M0[1, 0] * tn[i, 1] + M0[2, 0] * tn[i, 2]
        ny = M0[0, 1] * tn[i, 0] + M0[1, 1] * tn[i, 1] + M0[2, 1] * tn[i, 2]
        nz = M0[0, 2] * tn[i, 0] + M0[1, 2] * tn[i, 1] + M0[2, 2] * tn[i, 2]
        V[i, 0], V[i, 1], V[i, 2] = x, y, z
        N[i, 0], N[i, 1], N[i, 2] = nx, ny, nz
        if z <= 1.0 or nx * x + ny * y + nz * z >= 0.0:
            continue
        u = int(np.floor(fx * x / z + cx + 0.5))
        v = int(np.floor(fy * y / z + cy + 0.5))
        if u < 0 or u >= W or v < 0 or v >= H:
            continue
        c = v * W + u
        if z < zbuf[c]:
            zbuf[c] = z
            grid[c] = i
    return grid, V, N


@njit(cache=True, nogil=True)
def _exp(x):
    """The rigid motion of the twist (rotation vector x[:3], then translation x[3:])."""
    w0, w1, w2 = x[0], x[1], x[2]
    th = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    K = np.array([[0.0, -w2, w1], [w2, 0.0, -w0], [-w1, w0, 0.0]])
    if th < 1e-12:
        R = np.eye(3) + K
    else:
        R = np.eye(3) + np.sin(th) / th * K + (1.0 - np.cos(th)) / (th * th) * (K @ K)
    T = np.eye(4)
    T[:3, :3] = R
    T[0, 3], T[1, 3], T[2, 3] = x[3], x[4], x[5]
    return T


@njit(cache=True, nogil=True, inline="always")
def _nearest_drawn(src, i, A, grid, V, camera, reach, md2):
    """Scan point i moved by A, and the nearest map point drawn within `reach` pixels of its projection (camera:
    fx, fy, cx, cy, W, H of the drawn view) closer than sqrt(md2): (its index or -1, the squared distance, the
    moved point)."""
    fx, fy, cx, cy, W, H = camera
    s0, s1, s2 = src[i, 0], src[i, 1], src[i, 2]
    px = A[0, 0] * s0 + A[0, 1] * s1 + A[0, 2] * s2 + A[0, 3]
    py = A[1, 0] * s0 + A[1, 1] * s1 + A[1, 2] * s2 + A[1, 3]
    pz = A[2, 0] * s0 + A[2, 1] * s1 + A[2, 2] * s2 + A[2, 3]
    j = -1
    best = md2
    if pz <= 1.0:
        return j, best, px, py, pz
    u0 = int(np.floor(fx * px / pz + cx + 0.5))
    v0 = int(np.floor(fy * py / pz + cy + 0.5))
    for dv in range(-reach, reach + 1):
        for du in range(-reach, reach + 1):
            u, v = u0 + du, v0 + dv
            if u < 0 or u >= W or v < 0 or v >= H:
                continue
            jj = grid[v * W + u]
            if jj < 0:
                continue
            ex, ey, ez = px - V[jj, 0], py - V[jj, 1], pz - V[jj, 2]
            d2 = ex * ex + ey * ey + ez * ez
            if d2 < best:
                best, j = d2, jj
    return j, best, px, py, pz


@njit(cache=True, nogil=True)
def icp(src, grid, V, N, fx, fy, cx, cy, W, H, A, max_dist, k, iterations, tol, reach):
    """A (scan camera -> predicted camera) refined; returns (A, correspondences used in the last step). Each scan
    point's correspondence is the nearest map point drawn within `reach` pixels of its own (0: that pixel's)."""
    A = A.copy()
    md2 = max_dist * max_dist
    used = 0
    for _ in range(iterations):
        Hm = np.zeros((6, 6))
        b = np.zeros(6)
        J = np.zeros(6)
        used = 0
        for i in range(src.shape[0]):
            j, _, px, py, pz = _nearest_drawn(src, i, A, grid, V, (fx, fy, cx, cy, W, H), reach, md2)
            if j < 0:
                continue
            dx, dy, dz = px - V[j, 0], py - V[j, 1], pz - V[j, 2]
            nx, ny, nz = N[j, 0], N[j, 1], N[j, 2]
            r = dx * nx + dy * ny + dz * nz
            if abs(r) >= k:
                continue
            t = 1.0 - (r / k) ** 2
            w = t * t  # Tukey's biweight
            J[0], J[1], J[2] = py * nz - pz * ny, pz * nx - px * nz, px * ny - py * nx
            J[3], J[4], J[5] = nx, ny, nz
            for a in range(6):
                b[a] -= w * J[a] * r
                for c in range(6):
                    Hm[a, c] += w * J[a] * J[c]
            used += 1
        if used < 6:
            break
        x = np.linalg.solve(Hm, b)
        A = _exp(x) @ A
        if np.sqrt(np.sum(x * x)) < tol:
            break
    return A, used


@njit(cache=True, nogil=True)
def evaluate(src, grid, V, fx, fy, cx, cy, W, H, A, max_dist):
    """(fitness, inlier RMSE): the share of scan points with a drawn map point within max_dist among the 3 x 3
    pixels around theirs, and the RMS of those nearest distances."""
    n = src.shape[0]
    inliers = 0
    sq = 0.0
    md2 = max_dist * max_dist
    for i in range(n):
        j, d2, _, _, _ = _nearest_drawn(src, i, A, grid, V, (fx, fy, cx, cy, W, H), 1, md2)
        if j >= 0:
            inliers += 1
            sq += d2
    fitness = inliers / n if n else 0.0
    rmse = np.sqrt(sq / inliers) if inliers else 0.0
    return fitness, rmse


class ProjectiveICP:
    """The two ICP stages of the tracker (coarse, fine) on one drawn view of the map per scan."""

    def __init__(self, camera_matrix: np.ndarray, size: tuple[int, int], cell_px: float) -> None:
        K = np.asarray(camera_matrix, np.float64)
        g = float(cell_px)
        self.f = (K[0, 0] / g, K[1, 1] / g, K[0, 2] / g, K[1, 2] / g)
        self.W, self.H = int(np.ceil(size[0] / g)) + 2, int(np.ceil(size[1] / g)) + 2

    def register(
        self,
        src: np.ndarray,
        map_points: np.ndarray,
        map_normals: np.ndarray,
        init: np.ndarray,
        stages: list[tuple[float, int, float, int]],
        eval_mm: float,
    ) -> tuple[np.ndarray, float, float] | None:
        """(pose, fitness, inlier RMSE) from init through the stages (distance = Tukey k, iterations, tolerance,
        reach in drawn pixels), or None when no scan point found the map."""
        fx, fy, cx, cy = self.f
        M0 = np.ascontiguousarray(init, np.float64)
        grid, V, N = model_view(
            np.ascontiguousarray(map_points, np.float64),
            np.ascontiguousarray(map_normals, np.float64),
            M0,
            fx,
            fy,
            cx,
            cy,
            self.W,
            self.H,
        )
        src = np.ascontiguousarray(src, np.float64)
        A = np.eye(4)
        for dist, iterations, tol, reach in stages:
            A, used = icp(src, grid, V, N, fx, fy, cx, cy, self.W, self.H, A, dist, dist, iterations, tol, reach)
            if used < 6:
                return None
        fitness, rmse = evaluate(src, grid, V, fx, fy, cx, cy, self.W, self.H, A, eval_mm)
        return M0 @ A, float(fitness), float(rmse)
