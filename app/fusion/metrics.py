"""A fused model against the truth: the mesh's vertex error, its completeness, and the poses' drift.

- accuracy: per mesh vertex, its distance to the true surface: to the plane of the nearest sample point (its
  tangent plane) when that point is within 1 mm, else to the point itself.
- completeness: the share of the true surface seen over the sequence (sample points visible, lit and facing the
  camera in some frame: drivers/sim/truth.py) that lies within 1 mm of the mesh (exact point-to-triangle distance).
- drift: the pose error E = M_true^-1 M_est of a scan: its angle (deg) and the mean displacement it gives the
  true surface (mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.fusion.open3d_import import open3d
from app.fusion.registration import rotation_deg
from core.surface_sample import SurfaceSample

NEAR_MM = 1.0


@dataclass
class Accuracy:
    mean_mm: float
    rms_mm: float
    p99_mm: float
    vertices: int


def vertex_errors(vertices: np.ndarray, truth: SurfaceSample) -> np.ndarray:
    o3d = open3d()
    nns = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(truth.points.astype(np.float32)))
    nns.knn_index()
    idx, _ = nns.knn_search(o3d.core.Tensor(np.ascontiguousarray(vertices, np.float32)), 1)
    i = idx.numpy()[:, 0]
    d = vertices - truth.points[i]
    euclid = np.linalg.norm(d, axis=1)
    plane = np.abs(np.einsum("ij,ij->i", d, truth.normals[i]))
    return np.where(euclid <= NEAR_MM, plane, euclid)


def accuracy(vertices: np.ndarray, truth: SurfaceSample) -> Accuracy:
    e = vertex_errors(vertices, truth)
    if not len(e):
        return Accuracy(float("nan"), float("nan"), float("nan"), 0)
    return Accuracy(float(e.mean()), float(np.sqrt((e**2).mean())), float(np.percentile(e, 99)), len(e))


def completeness(vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray) -> float:
    """The share of `points` within NEAR_MM of the mesh."""
    if not len(points):
        return float("nan")
    if not len(triangles):
        return 0.0
    o3d = open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.ascontiguousarray(vertices, np.float32)),
        o3d.core.Tensor(np.ascontiguousarray(triangles, np.uint32)),
    )
    d = scene.compute_distance(o3d.core.Tensor(np.ascontiguousarray(points, np.float32))).numpy()
    return float((d <= NEAR_MM).mean())


def pose_error(estimate: np.ndarray, true: np.ndarray, points: np.ndarray) -> tuple[float, float]:
    """(degrees, mm): the angle of E = true^-1 estimate, and the mean displacement E gives `points` (model frame:
    where true maps them)."""
    E = np.linalg.inv(true) @ estimate
    X = points
    moved = X @ E[:3, :3].T + E[:3, 3]
    return rotation_deg(E[:3, :3]), float(np.linalg.norm(moved - X, axis=1).mean())
