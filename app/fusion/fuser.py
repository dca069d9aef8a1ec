"""Registration and integration of a stream of scans into one model, with its counts and per-scan times."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from app.fusion.registration import Tracker, TrackResult, TrackSettings, for_footprint
from app.fusion.scan import Scan, ScanMaker
from app.fusion.volume import Volume, box_surface_mm2, check_memory
from core.calibration import Calibration
from core.trajectory import PoseRow

DEFAULT_VOXEL_MM = 0.5


@dataclass
class FuseStats:
    scans: int = 0
    integrated: int = 0
    dropped: int = 0  # failed registration: not integrated
    dropped_in_a_row: int = 0
    track_s: list[float] = field(default_factory=list)  # thread CPU time per tracked scan
    integrate_s: list[float] = field(default_factory=list)


class Fuser:
    def __init__(
        self,
        calibration: Calibration,
        depth_range_mm: tuple[float, float],
        volume_mm: tuple[float, ...] | None = None,
        voxel_mm: float = DEFAULT_VOXEL_MM,
        settings: TrackSettings | None = None,
        min_weight: float = 3.0,
    ) -> None:
        w, h = calibration.camera_size
        far = depth_range_mm[1] if volume_mm is None else min(depth_range_mm[1], volume_mm[5])
        if volume_mm is not None:
            surface = box_surface_mm2(volume_mm)
        else:  # the camera's view at the far end of the depth range, front and back
            K = calibration.camera_matrix
            surface = 2.0 * (w * far / K[0, 0]) * (h * far / K[1, 1])
        check_memory(voxel_mm, surface)
        self.maker = ScanMaker(calibration, volume_mm)
        if settings is None:  # (given settings are taken as they are)
            footprint = 0.5 * (depth_range_mm[0] + depth_range_mm[1]) / calibration.camera_matrix[0, 0]
            settings = for_footprint(TrackSettings(), footprint)
        self.tracker = Tracker(settings, self.maker.K, (w, h))
        self.volume = Volume(voxel_mm, self.maker.K, (w, h), far, surface, min_weight)
        self.stats = FuseStats()
        self.poses: list[PoseRow] = []

    def scan(self, depth: np.ndarray, colour: np.ndarray, frame_id: int) -> Scan:
        return self.maker.make(depth, colour, frame_id)

    def track(self, scan: Scan) -> TrackResult:
        t0 = time.thread_time()
        st = self.tracker.settings
        # (the map's colours serve the coloured ICP only: without it the colour is not smoothed and sampled)
        pts, nrm, rgb = self.maker.points_and_normals(scan.depth, st.stride, scan.colour if st.colour else None)
        res = self.tracker.track(pts, nrm, rgb, scan.frame_id)
        self.stats.track_s.append(time.thread_time() - t0)
        self.stats.scans += 1
        status = "ok" if res.ok else "dropped"
        self.poses.append(PoseRow(len(self.poses), scan.frame_id, status, res.pose))
        if res.ok:
            self.stats.dropped_in_a_row = 0
        else:
            self.stats.dropped += 1
            self.stats.dropped_in_a_row += 1
        return res

    def integrate(self, scan: Scan, pose: np.ndarray) -> None:
        t0 = time.thread_time()
        self.volume.integrate(scan.depth, scan.colour, pose)
        self.stats.integrate_s.append(time.thread_time() - t0)
        self.stats.integrated += 1

    def add(self, scan: Scan) -> TrackResult:
        """Track a scan and, when it registered, integrate it."""
        res = self.track(scan)
        if res.ok:
            self.integrate(scan, res.pose)
        return res

    def mesh(self) -> object:
        return self.volume.mesh()
