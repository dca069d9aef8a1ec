"""Surface normals from a depth grid: the cross product of the grid's tangents along a row and a column.

grid_normals states the rule in numpy; point_normals, which every exported cloud goes through, runs the same rule
compiled (_normals_kernel: one pass for the tangents, running sums for the window), to the float rounding of the
order of its sums (tests/app/test_normals.py).
"""

from __future__ import annotations

import cv2
import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)

MAX_STEP = 0.05  # a neighbour more than 5 % of the depth away is across an edge, not on the same surface


def grid_points(depth: np.ndarray, ray: np.ndarray) -> np.ndarray:
    """H x W x 3 camera-frame points (mm) of a depth map over normalised rays (x/z, y/z); 0 depth gives 0."""
    return np.stack([ray[..., 0] * depth, ray[..., 1] * depth, depth], axis=-1).astype(np.float32)


def _tangent(P: np.ndarray, valid: np.ndarray, axis: int) -> np.ndarray:
    """Per pixel the grid's tangent along an axis: the central difference where both neighbours are on the surface,
    else the one-sided one that is, else NaN."""
    z = P[..., 2]
    fwd = np.full_like(P, np.nan)
    ok = np.zeros(valid.shape, bool)
    n = P.shape[axis]
    a = [slice(None)] * 2
    b = [slice(None)] * 2
    a[axis], b[axis] = slice(0, n - 1), slice(1, n)
    a, b = tuple(a), tuple(b)
    step = P[b] - P[a]
    fine = valid[a] & valid[b] & (np.abs(z[b] - z[a]) <= MAX_STEP * z[a])
    fwd[a] = np.where(fine[..., None], step, np.nan)  # fwd[i] = P[i+1] - P[i]
    ok[a] = fine
    bwd = np.full_like(P, np.nan)
    okb = np.zeros(valid.shape, bool)
    bwd[b] = fwd[a]  # bwd[i] = P[i] - P[i-1]
    okb[b] = fine
    both = ok & okb
    out = np.where(ok[..., None], fwd, bwd)
    out[both] = 0.5 * (fwd[both] + bwd[both])
    return out


def _window_mean(t: np.ndarray, window: int) -> np.ndarray:
    """Per pixel the mean of the finite tangents in the window x window square around it (NaN where none): the sum
    telescopes to a difference across the window, so random depth noise weighs less (a systematic ripple of the
    decoded depth, wider than the window, does not average out)."""
    ok = np.isfinite(t).all(axis=-1)
    w = cv2.boxFilter(ok.astype(np.float64), -1, (window, window), normalize=False, borderType=cv2.BORDER_CONSTANT)
    out = np.empty_like(t)
    filled = np.where(ok[..., None], t, 0.0)
    for c in range(3):
        out[..., c] = cv2.boxFilter(
            filled[..., c], -1, (window, window), normalize=False, borderType=cv2.BORDER_CONSTANT
        )
    with np.errstate(invalid="ignore", divide="ignore"):
        out /= w[..., None]
    out[w == 0] = np.nan
    return out


def grid_normals(depth: np.ndarray, ray: np.ndarray, window: int = 1) -> np.ndarray:
    """H x W x 3 unit normals (float32) of the surface a depth map samples, facing the camera (n . P < 0); NaN at
    pixels without depth or without a neighbour on the same surface along a row or a column. window (odd): the
    tangents are averaged over that square first (only those within a surface: MAX_STEP), for less noise at the
    price of rounding edges by window // 2 pixels."""
    valid = depth > 0
    P = grid_points(depth, ray).astype(np.float64)
    tx = _tangent(P, valid, axis=1)
    ty = _tangent(P, valid, axis=0)
    if window > 1:
        tx, ty = _window_mean(tx, window), _window_mean(ty, window)
    n = np.cross(ty, tx)  # x right, y down, z forward: ty x tx points back at the camera on a frontal surface
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        flip = np.sum(n * P, axis=-1) > 0
    n[flip] *= -1
    n[~valid] = np.nan
    return n.astype(np.float32)


# The square the exported normals average their tangents over (PLY): per-pixel differences carry the depth noise
# whole (a median 4.5 degrees off on the virtual rig's plane at 320x240), a 5 x 5 square a fifth of that.
EXPORT_WINDOW = 5


def point_normals(depth: np.ndarray, ray: np.ndarray, window: int = EXPORT_WINDOW) -> np.ndarray:
    """N x 3 float32 unit normals of the pixels with depth, in row-major pixel order (the order of depth[depth > 0],
    as the point cloud's points); 0 0 0 where grid_normals has none (no neighbour on the same surface)."""
    if window < 1 or window % 2 == 0:
        raise ValueError(f"window {window} must be odd")
    grid = np.empty((*depth.shape, 3), np.float32)
    _normals_kernel(np.ascontiguousarray(depth, np.float32), np.ascontiguousarray(ray, np.float64), window, grid)
    n = grid[depth > 0]
    n[~np.isfinite(n).all(axis=1)] = 0.0
    return n


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _tangent_at(P, valid, y, x, dy, dx, out, k, row):
    """grid_normals' tangent of pixel (y, x) along (dy, dx) into out[row, x, k:k+3] and whether it has one."""
    H, W = valid.shape
    z = P[y, x, 2]
    yf, xf, yb, xb = y + dy, x + dx, y - dy, x - dx
    fwd = yf < H and xf < W and valid[y, x] and valid[yf, xf] and abs(P[yf, xf, 2] - z) <= MAX_STEP * z
    bwd = yb >= 0 and xb >= 0 and valid[y, x] and valid[yb, xb] and abs(z - P[yb, xb, 2]) <= MAX_STEP * P[yb, xb, 2]
    for c in range(3):
        if fwd and bwd:
            out[row, x, k + c] = 0.5 * ((P[yf, xf, c] - P[y, x, c]) + (P[y, x, c] - P[yb, xb, c]))
        elif fwd:
            out[row, x, k + c] = P[yf, xf, c] - P[y, x, c]
        elif bwd:
            out[row, x, k + c] = P[y, x, c] - P[yb, xb, c]
        else:
            out[row, x, k + c] = 0.0
    return fwd or bwd


@njit(cache=True, nogil=True, error_model="numpy")
def _normals_kernel(depth, ray, window, out):
    """grid_normals(depth, ray, window) into out (H, W, 3) float32, a row at a time: each row's tangents (along the
    row: 0:3, the column: 3:6) and their counts (6, 7) summed over x - r .. x + r into a ring of the window's rows,
    whose running sum over y - r .. y + r gives row y's mean tangents, then their cross product (r = window // 2;
    zero outside the image, as cv2.BORDER_CONSTANT). Row buffers only: full-image sums cost more in page faults
    than in arithmetic."""
    H, W = depth.shape
    P = np.empty((H, W, 3))
    valid = depth > 0
    for y in range(H):
        for x in range(W):
            P[y, x, 0] = np.float64(np.float32(ray[y, x, 0] * depth[y, x]))  # (grid_points' float32 points)
            P[y, x, 1] = np.float64(np.float32(ray[y, x, 1] * depth[y, x]))
            P[y, x, 2] = np.float64(depth[y, x])
    r = window // 2
    trow = np.empty((1, W, 8))
    ring = np.zeros((window, W, 8))
    acc = np.zeros((W, 8))
    for yy in range(H + r):
        if yy < H:
            for x in range(W):
                trow[0, x, 6] = 1.0 if _tangent_at(P, valid, yy, x, 0, 1, trow, 0, 0) else 0.0
                trow[0, x, 7] = 1.0 if _tangent_at(P, valid, yy, x, 1, 0, trow, 3, 0) else 0.0
            slot = ring[yy % window]
            for c in range(8):
                s = 0.0
                for x in range(min(r, W)):
                    s += trow[0, x, c]
                for x in range(W):
                    if x + r < W:
                        s += trow[0, x + r, c]
                    slot[x, c] = s
                    if x - r >= 0:
                        s -= trow[0, x - r, c]
            acc += slot
        y = yy - r
        if y < 0:
            continue
        for x in range(W):
            _normal_at(P, valid, acc, y, x, out)
        if y - r >= 0:
            acc -= ring[(y - r) % window]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _normal_at(P, valid, acc, y, x, out):
    """out[y, x] from the window's summed tangents acc[x] (sums, then counts): ty x tx, unit, facing the camera."""
    nx_, ny_ = acc[x, 6], acc[x, 7]
    if not valid[y, x] or nx_ < 0.5 or ny_ < 0.5:
        out[y, x, 0] = out[y, x, 1] = out[y, x, 2] = np.nan
        return
    ax, ay, az = acc[x, 0] / nx_, acc[x, 1] / nx_, acc[x, 2] / nx_
    bx, by, bz = acc[x, 3] / ny_, acc[x, 4] / ny_, acc[x, 5] / ny_
    n0 = by * az - bz * ay
    n1 = bz * ax - bx * az
    n2 = bx * ay - by * ax
    norm = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if not norm > 0:
        out[y, x, 0] = out[y, x, 1] = out[y, x, 2] = np.nan
        return
    s = -1.0 if n0 * P[y, x, 0] + n1 * P[y, x, 1] + n2 * P[y, x, 2] > 0 else 1.0
    out[y, x, 0] = s * n0 / norm
    out[y, x, 1] = s * n1 / norm
    out[y, x, 2] = s * n2 / norm
