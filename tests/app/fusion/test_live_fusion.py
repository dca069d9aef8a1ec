"""Fusion in a live session: the fusion thread takes scans as decode workers offer them and never makes them wait."""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.capture import FrameSet
from app.decode.pipeline import FrameSetDecoder
from app.fusion.live import LiveFusion
from app.live_pipeline import LiveResult
from core.patterns import make_patterns
from drivers.base import Frame
from drivers.sim.rig import VirtualRig

pytest.importorskip("open3d")


def _results(n: int) -> tuple[VirtualRig, list[LiveResult]]:
    rig = VirtualRig.from_preset("turntable", camera_size=(640, 480), rotation_deg_per_frame=0.5)
    cal = rig.calibration
    cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
    ps = make_patterns("two-shot", cal.projector_size)
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    dec = FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm)
    frames = [Frame(rig.render(ps.images[k % 2]), k + 1, k, pattern=k % 2) for k in range(n + 2)]
    out = []
    for k in range(2, n + 2):
        pair = (frames[k], frames[k - 1]) if k % 2 == 0 else (frames[k - 1], frames[k])
        fs = FrameSet(pair, reversed_order=k % 2 == 0, previous=frames[k - 2])
        sm, depth = dec.stripes_and_depth([f.image for f in pair], 0 if k % 2 == 0 else 1, frames[k - 2].image)
        out.append(LiveResult(k, fs, sm, depth, 0.0, 0.0, 0))
    return rig, out


def test_every_offered_scan_is_tracked_or_counted_late_and_the_poses_follow_the_turn():
    rig, results = _results(8)
    fusion = LiveFusion(rig.calibration, rig.depth_range_mm, rig.scene.working_volume_mm, voxel_mm=1.0)
    t0 = time.monotonic()
    for r in results:  # as fast as decode workers could: nothing here may wait for the fusion thread
        fusion.offer(r)
    assert time.monotonic() - t0 < 1.0
    fusion.stop()
    s = fusion.fuser.stats
    assert fusion.error is None
    assert fusion.offered == 8 and s.scans + fusion.late == 8 and s.scans >= 1
    assert s.integrated + fusion.skipped + s.dropped == s.scans
    # offered one at a time (a slow camera), every scan is tracked and integrated
    rig, results = _results(6)
    fusion = LiveFusion(rig.calibration, rig.depth_range_mm, rig.scene.working_volume_mm, voxel_mm=1.0)
    for r in results:
        fusion.offer(r)
        deadline = time.monotonic() + 30
        while fusion.fuser.stats.scans < r.index - 1 and time.monotonic() < deadline:
            time.sleep(0.01)
    fusion.stop()
    s = fusion.fuser.stats
    assert (s.scans, fusion.late, s.dropped) == (6, 0, 0)
    first, last = results[0].frameset.newest.frame_id - 1, results[-1].frameset.newest.frame_id - 1
    true_last = rig.object_pose(first) @ np.linalg.inv(rig.object_pose(last))
    E = np.linalg.inv(true_last) @ fusion.fuser.poses[-1].pose
    assert np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1, 1))) < 1.5  # of 2.5 deg turned
