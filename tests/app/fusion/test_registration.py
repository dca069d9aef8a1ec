"""The tracker's failure test on a scan whose correspondences cannot fix the pose."""

from __future__ import annotations

import numpy as np
import pytest

from app.fusion.registration import Tracker

pytest.importorskip("open3d")

K = np.array([[900.0, 0.0, 320.0], [0.0, 900.0, 240.0], [0.0, 0.0, 1.0]])


def _wall(z_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat wall facing the camera: points on a 2 mm grid, 40 mm square, normals exactly toward the camera."""
    x, y = np.meshgrid(np.arange(-20.0, 20.0, 2.0), np.arange(-20.0, 20.0, 2.0))
    pts = np.stack([x.ravel(), y.ravel(), np.full(x.size, z_mm)], axis=1)
    nrm = np.tile([0.0, 0.0, -1.0], (len(pts), 1))
    return pts, nrm, np.full((len(pts), 3), 0.5)


def test_a_wall_facing_the_camera_is_dropped_as_a_singular_step_and_the_model_is_kept():
    """A plane fixes only its distance and tilt: the slide within it and the turn about its normal are free, so the
    Gauss-Newton step is singular. The scan is dropped with that reason, the map and the last pose stay as they were."""
    tracker = Tracker(camera_matrix=K, size=(640, 480))
    assert tracker.projective is not None
    assert tracker.track(*_wall(700.0), frame_id=1).ok
    cells, pose = len(tracker.map), tracker.pose.copy()
    res = tracker.track(*_wall(700.5), frame_id=2)
    assert not res.ok
    assert "singular" in res.reason, res.reason
    assert len(tracker.map) == cells
    np.testing.assert_array_equal(tracker.pose, pose)
