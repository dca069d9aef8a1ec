"""Scoring a calibration: against a known truth (virtual rig) and by scanning a flat board.

- `compare`: focal length errors (%), principal point errors (px), baseline |T| error (mm) and
  the rotation between the two R (deg).
- `plane_scan`: decode a Gray-code frame set of a flat surface, triangulate it with the
  calibration, fit a plane: the residual (mm) says how flat the calibration keeps a flat board;
  with a ground-truth depth map, the depth error (%).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from core.calibration import Calibration


def compare(cal: Calibration, truth: Calibration) -> dict[str, float]:
    """Errors of `cal` against `truth` (positive numbers; the worst of x and y)."""
    out: dict[str, float] = {}
    for dev in ("camera", "projector"):
        K, Kt = getattr(cal, f"{dev}_matrix"), getattr(truth, f"{dev}_matrix")
        out[f"{dev}_focal_error_pct"] = float(np.max(np.abs(np.diag(K)[:2] / np.diag(Kt)[:2] - 1)) * 100)
        out[f"{dev}_principal_error_px"] = float(np.max(np.abs(K[:2, 2] - Kt[:2, 2])))
    out["baseline_error_mm"] = float(abs(np.linalg.norm(cal.T) - np.linalg.norm(truth.T)))
    out["T_error_mm"] = float(np.linalg.norm(cal.T - truth.T))
    r, _ = cv2.Rodrigues(cal.R @ truth.R.T)
    out["rotation_error_deg"] = float(np.degrees(np.linalg.norm(r)))
    return out


@dataclass
class PlaneScan:
    points: int  # pixels with depth
    plane_rms_mm: float  # residual of a least-squares plane through the scanned points
    depth_error_pct: float = float("nan")  # |mean(Z - Z_true)| / mean(Z_true), if a truth is given
    depth_abs_error_pct: float = float("nan")  # median |Z - Z_true| / Z_true per pixel


def fit_plane(xyz: np.ndarray) -> tuple[np.ndarray, float]:
    """Plane (unit normal n, offset d: n.X = d) and the RMS distance of the points to it."""
    c = xyz.mean(axis=0)
    _, _, vt = np.linalg.svd(xyz - c, full_matrices=False)
    n = vt[-1]
    dist = (xyz - c) @ n
    return np.r_[n, n @ c], float(np.sqrt((dist**2).mean()))


def plane_scan(
    column: np.ndarray,
    cal: Calibration,
    depth_range_mm: tuple[float, float],
    true_depth: np.ndarray | None = None,
    mask: np.ndarray | None = None,
) -> PlaneScan:
    """Triangulate a decoded column map of a flat surface and score it."""
    from app.triangulate import Triangulator  # lazy: numba compiles on first use

    tri = Triangulator(cal, depth_range_mm)
    depth = tri.depth(np.where(mask, column, np.nan) if mask is not None else column)
    cloud = tri.points(depth)
    if len(cloud.xyz) < 100:
        return PlaneScan(len(cloud.xyz), float("nan"))
    _, rms = fit_plane(cloud.xyz.astype(np.float64))
    scan = PlaneScan(len(cloud.xyz), rms)
    if true_depth is not None:
        m = (depth > 0) & (true_depth > 0)
        if m.sum() >= 100:
            z, zt = depth[m].astype(np.float64), true_depth[m].astype(np.float64)
            scan.depth_error_pct = float(abs((z - zt).mean()) / zt.mean() * 100)
            scan.depth_abs_error_pct = float(np.median(np.abs(z - zt) / zt) * 100)
    return scan
