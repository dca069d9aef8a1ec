"""Whole-model ground truth: the true surface sample, the true poses, the hand-held path, and their files."""

from __future__ import annotations

import numpy as np
import pytest

from app.cli import main
from core.errors import InputError
from core.patterns import make_patterns
from core.surface_sample import read_surface_sample
from core.trajectory import read_trajectory
from drivers.sim.rig import VirtualRig
from drivers.sim.truth import inside, surface_sample


def _distances(points: np.ndarray, sample) -> tuple[np.ndarray, np.ndarray]:
    """Each point's distance to its nearest sample point, and to that point's tangent plane (brute force)."""
    near, plane = np.empty(len(points)), np.empty(len(points))
    for a in range(0, len(points), 100):
        p = points[a : a + 100]
        d2 = ((p[:, None, :] - sample.points[None, :, :]) ** 2).sum(axis=2)
        i = d2.argmin(axis=1)
        near[a : a + 100] = np.sqrt(d2[np.arange(len(p)), i])
        plane[a : a + 100] = np.abs(np.einsum("ij,ij->i", p - sample.points[i], sample.normals[i]))
    return near, plane


@pytest.mark.parametrize(("scene", "overrides"), [("turntable", {"rotation_deg_per_frame": 7.0}), ("handheld", {})])
def test_true_points_of_a_moving_frame_lie_on_the_sample_mapped_by_the_true_pose(scene, overrides):
    rig = VirtualRig.from_preset(scene, camera_size=(160, 120), **overrides)
    sample = surface_sample(rig.moving_shapes, spacing_mm=1.0)
    ps = make_patterns("two-shot", rig.projector_size)
    for k in range(6):
        rig.render(ps.images[k % 2])
    gt = rig.ground_truth
    M = rig.object_pose(5)
    assert not np.allclose(M, np.eye(4))  # it moved
    pts = gt.points.reshape(-1, 3)[gt.visible.ravel()].astype(np.float64)
    obj = (pts - M[:3, 3]) @ M[:3, :3]  # camera at frame 5 -> object frame
    near, plane = _distances(obj[::6], sample)
    on_object = near < 1.0  # the object's pixels (the wall and the stand are far from its surface)
    assert on_object.sum() > 150
    # (the last few per cent: where two parts meet, the nearest sample point may lie on the other part)
    assert np.percentile(plane[on_object], 97) < 0.03, np.percentile(plane[on_object], [50, 97])


def test_sample_is_the_union_surface_uniform_outward_and_painted():
    rig = VirtualRig.from_preset("turntable")
    shapes = rig.moving_shapes
    s = surface_sample(shapes, spacing_mm=1.0)
    for shape in shapes:  # no sample point is inside any part
        assert not inside(shape, s.points).any()
    centre = np.array([0.0, -14.0, 770.0])  # the head's: normals point away from it on the head
    head = np.linalg.norm(s.points - centre, axis=1) < 40
    assert head.sum() == 0 or (np.einsum("ij,ij->i", s.points[head] - centre, s.normals[head]) > 0).all()
    far = np.abs(s.points[:, 1] - -14.0) < 20  # the head's equator band faces outward
    assert (np.einsum("ij,ij->i", s.points[far] - centre, s.normals[far]) > 0).mean() > 0.99
    assert len(np.unique(s.colors, axis=0)) > 8  # the painted patches, not one colour
    with pytest.raises(InputError, match="no moving object"):
        surface_sample([])


def test_handheld_path_starts_at_the_scene_moves_smoothly_and_keeps_going():
    rig = VirtualRig.from_preset("handheld", camera_size=(160, 120))
    assert np.allclose(rig.object_pose(0), np.eye(4))
    centre = np.array([0.0, -14.0, 770.0])
    track = np.array([rig.object_pose(k)[:3, :3] @ centre + rig.object_pose(k)[:3, 3] for k in range(400)])
    step = np.linalg.norm(np.diff(track, axis=0), axis=1)
    assert step.max() * 60 < 60  # below 6 cm/s
    assert np.abs(np.diff(step)).max() < 0.05  # no kink: the speed changes smoothly
    assert np.ptp(track, axis=0).max() > 15  # it does wander
    with pytest.raises(InputError, match="wander_mm"):
        VirtualRig.from_preset("handheld", wander_mm=[1, 2])


def test_sim_render_writes_the_surface_sample_and_true_poses(tmp_path):
    out = tmp_path / "tt"
    argv = ["sim", "render", "--scene", "turntable", "--scheme", "two-shot", "--camera-size", "160x120"]
    assert main([*argv, "--set", "rotation_deg_per_frame=3", "--cycles", "2", "--out", str(out)]) == 0
    sample = read_surface_sample(out / "ground_truth" / "surface.ply")
    assert len(sample.points) > 10000
    assert np.allclose(np.linalg.norm(sample.normals, axis=1), 1.0, atol=1e-5)
    rows = read_trajectory(out / "ground_truth" / "poses.csv")
    rig = VirtualRig.from_preset("turntable", camera_size=(160, 120), rotation_deg_per_frame=3)
    assert [r.frame_id for r in rows] == [1, 2, 3, 4] and {r.status for r in rows} == {"true"}
    for k, r in enumerate(rows):
        assert np.allclose(r.pose, np.linalg.inv(rig.object_pose(k)), atol=1e-6)
    import yaml

    meta = yaml.safe_load((out / "dump.yaml").read_text())
    assert meta["working_volume_mm"] == [-70, 70, -80, 71, 700, 840]
