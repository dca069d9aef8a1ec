"""Surface normals from a depth grid: the cross product of the grid's tangents along a row and a column."""

from __future__ import annotations

import cv2
import numpy as np

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
    n = grid_normals(depth, ray, window)[depth > 0]
    n[~np.isfinite(n).all(axis=1)] = 0.0
    return n
