"""Registration and integration of a stream of scans into one model, with its counts and per-scan times."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from app.fusion.projective import ProjectiveICP
from app.fusion.refine import Cloud, refine_poses
from app.fusion.registration import Tracker, TrackResult, TrackSettings, for_footprint
from app.fusion.scan import Scan, ScanMaker
from app.fusion.volume import Volume, box_surface_mm2, check_memory
from core.calibration import Calibration
from core.trajectory import PoseRow

DEFAULT_VOXEL_MM = 0.5
# with no motion known yet (the model is one scan), a scan this many frames (0.5 s at 60 frames/s) or more after it
# starts the model over from itself: the object may have turned far beyond the widest jump gate, and on a nearly
# symmetric object a far side can fit the first scan near its pose (docs/performance.md, "Live fusion at 60 frames/s")
RESTART_GAP_FRAMES = 30
REFINE_PASSES = 2  # the second makes the views agree more with each other (docs/performance.md, "Whole models")


@dataclass
class FuseStats:
    scans: int = 0
    integrated: int = 0
    dropped: int = 0  # failed registration: not integrated
    dropped_in_a_row: int = 0
    restarts: int = 0  # the model started over from a scan long after its only one (RESTART_GAP_FRAMES)
    tracking_dropped: int = 0  # failed registration while tracking (before any refinement)
    refine_s: float = 0.0  # CPU time of the refinement and the integration again
    track_s: list[float] = field(default_factory=list)  # thread CPU time per tracked scan
    integrate_s: list[float] = field(default_factory=list)
    scan_s: list[float] = field(default_factory=list)  # thread CPU time making each scan (before tracking)


class Fuser:
    def __init__(
        self,
        calibration: Calibration,
        depth_range_mm: tuple[float, float],
        volume_mm: tuple[float, ...] | None = None,
        voxel_mm: float = DEFAULT_VOXEL_MM,
        settings: TrackSettings | None = None,
        min_weight: float = 3.0,
        keep: bool = False,
    ) -> None:
        """keep: hold every tracked scan (its depth and colour cut to their box, and its registration points) for
        `refine`."""
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
        self._tracker_args = (settings, self.maker.K, (w, h))
        self.volume = Volume(voxel_mm, self.maker.K, (w, h), far, surface, min_weight)
        self._volume_args = (voxel_mm, self.maker.K, (w, h), far, surface, min_weight)
        self.keep = keep
        self._kept: list[tuple[tuple[Scan, int, int], Cloud | None]] = []
        self.stats = FuseStats()
        self.poses: list[PoseRow] = []

    def scan(self, depth: np.ndarray, colour: np.ndarray, frame_id: int) -> Scan:
        t0 = time.thread_time()
        scan = self.maker.make(depth, colour, frame_id)
        self.stats.scan_s.append(time.thread_time() - t0)
        return scan

    def track(self, scan: Scan) -> TrackResult:
        t0 = time.thread_time()
        first = self.tracker.frame
        if self.tracker.accepted == 1 and first is not None and scan.frame_id - first >= RESTART_GAP_FRAMES:
            self._restart()
        st = self.tracker.settings
        # (the map's colours serve the coloured ICP only: without it the colour is not smoothed and sampled)
        depth = scan.depth if scan.track_depth is None else scan.track_depth
        pts, nrm, rgb = self.maker.points_and_normals(depth, st.stride, scan.colour if st.colour else None)
        res = self.tracker.track(pts, nrm, rgb, scan.frame_id)
        self.stats.track_s.append(time.thread_time() - t0)
        if self.keep:
            self._kept.append((_cut(scan), self._cloud(pts, nrm)))
        self.stats.scans += 1
        status = "ok" if res.ok else "dropped"
        self.poses.append(PoseRow(len(self.poses), scan.frame_id, status, res.pose))
        if res.ok:
            self.stats.dropped_in_a_row = 0
        else:
            self.stats.dropped += 1
            self.stats.tracking_dropped += 1
            self.stats.dropped_in_a_row += 1
        return res

    def _restart(self) -> None:
        """An empty model, whose frame the next scan defines (the counts go on)."""
        self.tracker = Tracker(*self._tracker_args)
        self.volume = Volume(*self._volume_args)
        self._kept.clear()
        self.poses.clear()
        self.stats.restarts += 1

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

    def _cloud(self, pts: np.ndarray, nrm: np.ndarray) -> Cloud | None:
        """The points the tracker registers (app/fusion/registration.py: those facing the camera)."""
        ray = pts / np.linalg.norm(pts, axis=1, keepdims=True)
        facing = -np.einsum("ij,ij->i", nrm, ray) >= np.cos(np.radians(self.tracker.settings.max_incidence_deg))
        return Cloud(pts[facing], nrm[facing]) if facing.sum() >= 50 else None

    def refine(self, passes: int = REFINE_PASSES) -> None:
        """Every kept scan registered again against the other views (app/fusion/refine.py) and the volume built
        again from the refined poses; the pose rows and counts follow."""
        if not self.keep:
            raise ValueError("Fuser.refine needs the scans: make the Fuser with keep=True")
        t0 = time.thread_time()
        clouds = [c for _, c in self._kept]
        ok = [r.status == "ok" for r in self.poses]
        st = self.tracker.settings
        icp = self.tracker.projective or ProjectiveICP(self.maker.K, self.maker.size, st.stride)
        poses, registered = [r.pose for r in self.poses], ok
        for _ in range(passes):  # each pass against the map of the poses before it
            poses, registered = refine_poses(clouds, poses, registered, st, icp)
        self.volume = Volume(*self._volume_args)
        self.stats.integrated = 0
        self.stats.integrate_s = []
        for k, ((cut, _), pose, good) in enumerate(zip(self._kept, poses, registered, strict=True)):
            row = self.poses[k]
            self.poses[k] = PoseRow(row.scan, row.frame_id, "ok" if good else "dropped", pose)
            if good:
                self.integrate(_uncut(cut, self.maker.size), pose)
        self.stats.dropped = sum(not g for g in registered)
        self.stats.refine_s = time.thread_time() - t0

    def mesh(self) -> object:
        return self.volume.mesh()


def _cut(scan: Scan) -> tuple[Scan, int, int]:
    """The scan's depth and colour within the box of its pixels with depth, and the box's corner (row, column)."""
    rows = np.flatnonzero((scan.depth > 0).any(axis=1))
    cols = np.flatnonzero((scan.depth > 0).any(axis=0))
    if not len(rows):
        return Scan(scan.depth[:0, :0].copy(), scan.colour[:0, :0].copy(), scan.frame_id), 0, 0
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    return Scan(scan.depth[r0:r1, c0:c1].copy(), scan.colour[r0:r1, c0:c1].copy(), scan.frame_id), int(r0), int(c0)


def _uncut(cut: tuple[Scan, int, int], size: tuple[int, int]) -> Scan:
    part, r0, c0 = cut
    w, h = size
    depth = np.zeros((h, w), np.float32)
    colour = np.zeros((h, w, 3), np.uint8)
    dh, dw = part.depth.shape
    depth[r0 : r0 + dh, c0 : c0 + dw] = part.depth
    colour[r0 : r0 + dh, c0 : c0 + dw] = part.colour
    return Scan(depth, colour, part.frame_id)
