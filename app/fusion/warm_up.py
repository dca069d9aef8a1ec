"""Fusion's first scan made before capture starts: Open3D's volume and the tracking kernels loaded (or compiled).

A live session's fusion thread would otherwise spend its first ~1-3 s of scans on loading them, while every scan
that came meanwhile counted as late and the object moved on. The warm-up runs a throwaway Fuser over a synthetic
scene (a tilted plane through the working volume) with coarse voxels, so no model and little memory are involved.
"""

from __future__ import annotations

import numpy as np

from app.fusion.fuser import Fuser
from core.calibration import Calibration

WARM_UP_VOXEL_FACTOR = 4.0  # the throwaway volume's voxels, x the session's: the same kernels, less memory


def warm_up(
    calibration: Calibration,
    depth_range_mm: tuple[float, float],
    volume_mm: tuple[float, ...] | None,
    voxel_mm: float,
) -> None:
    """Track two synthetic scans and integrate one, in a Fuser that is then dropped."""
    fuser = Fuser(calibration, depth_range_mm, volume_mm, voxel_mm * WARM_UP_VOXEL_FACTOR)
    w, h = calibration.camera_size
    z0, z1 = depth_range_mm if volume_mm is None else (max(depth_range_mm[0], volume_mm[4]), volume_mm[5])
    K = calibration.camera_matrix
    cx, cy = (K[0, 2], K[1, 2]) if volume_mm is None else _centre_pixel(K, volume_mm)
    xs = np.arange(w, dtype=np.float32)[None, :] - np.float32(cx)
    ys = np.arange(h, dtype=np.float32)[:, None] - np.float32(cy)
    depth = (0.5 * (z0 + z1) + 0.05 * (z1 - z0) * (xs + 0.5 * ys) / max(w, h)).astype(np.float32)
    colour = np.full((h, w, 3), 128, np.uint8)
    for frame_id in (1, 2):
        scan = fuser.scan(depth, colour, frame_id)
        res = fuser.track(scan)
        if res.ok and frame_id == 1:
            fuser.integrate(scan, res.pose)
    fuser.mesh()


def _centre_pixel(K: np.ndarray, volume_mm: tuple[float, ...]) -> tuple[float, float]:
    """The pixel the working volume's centre projects to (the synthetic plane's tilt is about it)."""
    x = 0.5 * (volume_mm[0] + volume_mm[1])
    y = 0.5 * (volume_mm[2] + volume_mm[3])
    z = 0.5 * (volume_mm[4] + volume_mm[5])
    return K[0, 0] * x / z + K[0, 2], K[1, 1] * y / z + K[1, 2]
