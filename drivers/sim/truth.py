"""Ground truth for whole models: the moving object's true surface as a dense point sample, and its poses.

The object is the union of a scene's shapes marked `moves` (one rigid body, drivers/sim/motion.py); its
frame is the camera frame at frame 0, so the true pose of frame k is `VirtualRig.object_pose(k)`.

Each closed shape (ellipsoid, sphere, cylinder, box) is sampled uniformly by area at about `spacing_mm`
between neighbours; a point inside another of the object's shapes is not on the union's surface and is
left out. Normals point outward; colours are the shapes' albedo (their texture) as the rig paints it.
"""

from __future__ import annotations

import numpy as np

from core.errors import InputError
from core.surface_sample import SurfaceSample
from drivers.sim.shapes import Box, Cylinder, Ellipsoid, Shape, Sphere

_INSIDE_MARGIN = 1e-6  # relative: a point on another shape's surface counts as outside it


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _ellipsoid(axes: np.ndarray, spacing: float, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Local points, normals and faces, uniform by area: sphere directions u, x = A u, kept with probability
    proportional to the area element det(A) |A^-1 u| (rejection)."""
    a, b, c = axes
    p = 1.6
    area = 4 * np.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3) ** (1 / p)  # Knud Thomsen's formula
    n_keep = int(area / spacing**2)
    u = _unit(rng, 4 * n_keep)
    w = np.linalg.norm(u / axes, axis=1)
    keep = rng.uniform(0, w.max(), len(w)) < w
    x = u[keep][:n_keep] * axes
    nrm = x / axes**2
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return x, nrm, np.zeros(len(x), np.int8)


def _cylinder(r: float, h: float, spacing: float, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    n_side = int(2 * np.pi * r * h / spacing**2)
    n_cap = int(np.pi * r * r / spacing**2)
    th = rng.uniform(0, 2 * np.pi, n_side)
    side = np.stack([r * np.sin(th), rng.uniform(-h / 2, h / 2, n_side), -r * np.cos(th)], axis=1)
    side_n = np.stack([np.sin(th), np.zeros(n_side), -np.cos(th)], axis=1)
    rr = r * np.sqrt(rng.uniform(0, 1, 2 * n_cap))
    tc = rng.uniform(0, 2 * np.pi, 2 * n_cap)
    sign = np.repeat([-1.0, 1.0], n_cap)
    cap = np.stack([rr * np.sin(tc), sign * h / 2, -rr * np.cos(tc)], axis=1)
    cap_n = np.stack([np.zeros(2 * n_cap), sign, np.zeros(2 * n_cap)], axis=1)
    faces = np.concatenate([np.zeros(n_side, np.int8), np.ones(2 * n_cap, np.int8)])
    return np.concatenate([side, cap]), np.concatenate([side_n, cap_n]), faces


def _box(half: np.ndarray, spacing: float, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    pts, nrm, faces = [], [], []
    for face in range(6):
        axis, sign = face // 2, (1.0 if face % 2 else -1.0)
        others = [i for i in range(3) if i != axis]
        n = int(4 * half[others[0]] * half[others[1]] / spacing**2)
        x = np.zeros((n, 3))
        x[:, axis] = sign * half[axis]
        for i in others:
            x[:, i] = rng.uniform(-half[i], half[i], n)
        nn = np.zeros((n, 3))
        nn[:, axis] = sign
        pts.append(x)
        nrm.append(nn)
        faces.append(np.full(n, face, np.int8))
    return np.concatenate(pts), np.concatenate(nrm), np.concatenate(faces)


SAMPLED = (Sphere, Ellipsoid, Cylinder, Box)  # the closed shapes whose true surface is sampled


def can_sample(shapes: list[Shape]) -> bool:
    """Whether surface_sample takes every one of shapes (a relief or an open surface has no closed surface)."""
    return bool(shapes) and all(isinstance(s, SAMPLED) for s in shapes)


def _local_sample(s: Shape, spacing: float, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    if isinstance(s, Sphere):
        return _ellipsoid(np.full(3, float(s.radius)), spacing, rng)
    if isinstance(s, Ellipsoid):
        return _ellipsoid(np.asarray(s.semi_axes, np.float64), spacing, rng)
    if isinstance(s, Cylinder):
        return _cylinder(float(s.radius), float(s.height), spacing, rng)
    if isinstance(s, Box):
        return _box(np.asarray(s.half, np.float64), spacing, rng)
    raise InputError(f"shape {s.name or type(s).__name__!r}: no true-surface sample for a {type(s).__name__}")


def inside(s: Shape, X: np.ndarray) -> np.ndarray:
    """Whether camera-frame points lie strictly inside a closed shape."""
    x = s.point_to_local(np.ascontiguousarray(X, np.float64))
    m = 1.0 - _INSIDE_MARGIN
    if isinstance(s, Sphere):
        return np.einsum("ij,ij->i", x, x) < (s.radius * m) ** 2
    if isinstance(s, Ellipsoid):
        return ((x / np.asarray(s.semi_axes)) ** 2).sum(axis=1) < m
    if isinstance(s, Cylinder):
        return (x[:, 0] ** 2 + x[:, 2] ** 2 < (s.radius * m) ** 2) & (np.abs(x[:, 1]) < s.height / 2 * m)
    if isinstance(s, Box):
        return np.all(np.abs(x) < np.asarray(s.half) * m, axis=1)
    return np.zeros(len(X), bool)


def surface_sample(shapes: list[Shape], spacing_mm: float = 0.4, seed: int = 0) -> SurfaceSample:
    """The union surface of `shapes` (camera frame as posed), sampled at about spacing_mm."""
    if not shapes:
        raise InputError("the scene has no moving object (shapes marked `moves`): no object surface to sample")
    rng = np.random.default_rng(seed)
    pts, nrm, col = [], [], []
    for i, s in enumerate(shapes):
        xl, nl, faces = _local_sample(s, spacing_mm, rng)
        X = xl @ s.R.T + s.c
        N = nl @ s.R.T
        keep = np.ones(len(X), bool)
        for j, o in enumerate(shapes):
            if j != i:
                keep &= ~inside(o, X)
        X, N, faces = X[keep], N[keep], faces[keep]
        rho = np.clip(s.albedo(X, faces), 0.0, 1.0)
        pts.append(X)
        nrm.append(N)
        col.append(np.round(rho * 255).astype(np.uint8))
    return SurfaceSample(np.concatenate(pts), np.concatenate(nrm), np.concatenate(col))


def seen_by_camera(
    sample: SurfaceSample,
    pose: np.ndarray,
    truth_depth: np.ndarray,
    truth_lit: np.ndarray,
    camera_matrix: np.ndarray,
    distortion: np.ndarray,
    max_incidence_deg: float = 75.0,
    tolerance_mm: float = 0.5,
) -> np.ndarray:
    """Which sample points (object frame) a frame at `pose` (object -> camera, 4x4) shows lit: facing the camera
    within max_incidence_deg of its ray, and the frame's true depth at their pixel within tolerance_mm of theirs
    (so not hidden by a nearer surface)."""
    import cv2

    X = sample.points @ pose[:3, :3].T + pose[:3, 3]
    N = sample.normals @ pose[:3, :3].T
    ray = X / np.linalg.norm(X, axis=1, keepdims=True)
    facing = -np.einsum("ij,ij->i", N, ray) > np.cos(np.deg2rad(max_incidence_deg))
    uv, _ = cv2.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), camera_matrix, distortion)
    uv = np.rint(uv.reshape(-1, 2)).astype(np.int64)
    h, w = truth_depth.shape
    ok = facing & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h) & (X[:, 2] > 0)
    u, v = uv[ok, 0], uv[ok, 1]
    seen = np.zeros(len(X), bool)
    seen[np.nonzero(ok)[0]] = truth_lit[v, u] & (np.abs(truth_depth[v, u] - X[ok, 2]) < tolerance_mm)
    return seen
