"""Moving scenes on the virtual rig: the per-frame composition (drivers/sim/moving.py) against the full
re-precomputation, rotation against analytic geometry, still scenes unchanged, the options checked.

The moving path's kernels (drivers/sim/cast.py, moving.py) repeat numpy's arithmetic in numpy's order
(np.einsum sums three products as (0 + 2) + 1 here), so frames are compared bit for bit; a mismatch
after a numpy upgrade would show there first.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.patterns import two_shot_patterns
from drivers.sim.motion import rotation_matrix
from drivers.sim.rig import VirtualRig
from drivers.sim.scene import load_scene, parse_scene

SMALL = (160, 120)
GT_FIELDS = ("depth", "column", "row", "lit", "points")

# sha256 (first 16 hex digits) of two two-shot frames and the ground truth of each preset at 160x120
# with its default effects, rendered by the code before the moving rig existed (commit f5eb6dc).
STILL_BEFORE = {
    "charuco": "1e28b253ad37424b",
    "checkerboard": "32896f21209a6660",
    "colour_panel": "37d2a9c64606e11a",
    "cube": "5b408d0812c68a77",
    "cylinder": "ab7cec771207a867",
    "face": "f68f914af2413c95",
    "objects": "11dbd2a184ebed6b",
    "plane": "800d1f53ea729d7e",
    "plane_tilted": "806f0a72c0507ea6",
    "steps": "ed10830b7a88121d",
}


@pytest.mark.parametrize("name", sorted(STILL_BEFORE))
def test_still_scenes_render_bit_for_bit_as_before(name: str) -> None:
    rig = VirtualRig.from_preset(name, camera_size=SMALL)
    h = hashlib.sha256()
    for img in two_shot_patterns(rig.projector_size).images:
        h.update(rig.render(img).tobytes())
    gt = rig.ground_truth
    for f in GT_FIELDS:
        h.update(np.ascontiguousarray(getattr(gt, f)).tobytes())
    assert h.hexdigest()[:16] == STILL_BEFORE[name]


def mixed_scene() -> dict:
    """Every shape kind with a kernel, all moving, glossy and textured, over a static wall and post."""
    colors = [[[0.8, 0.2, 0.1], [0.1, 0.7, 0.2]], [[0.2, 0.2, 0.8], [0.9, 0.9, 0.2]]]
    patches = {"type": "patches", "cell_mm": [6, 6], "colors": colors}
    return {
        "description": "every shape moving",
        "depth_range_mm": [600, 900],
        "objects": [
            {"type": "sphere", "center": [-48, -10, 720], "radius": 30, "specular": 0.2, "moves": True},
            {"type": "box", "center": [45, 25, 745], "rotation_deg": [10, 30, 0], "size": [45, 45, 45], "moves": True},
            {
                "type": "cylinder",
                "center": [30, -50, 760],
                "rotation_deg": [0, 0, 90],
                "radius": 12,
                "height": 80,
                "moves": True,
            },
            {
                "type": "ellipsoid",
                "center": [-20, 40, 700],
                "semi_axes": [20, 14, 12],
                "rotation_deg": [10, 20, 30],
                "specular": 0.3,
                "moves": True,
                "texture": patches,
            },
            {"type": "plane", "center": [60, -40, 690], "size": [40, 30], "rotation_deg": [20, 10, 0], "moves": True},
            {
                "type": "relief",
                "center": [-60, 45, 780],
                "semi_axes": [22, 28],
                "depth": 18,
                "moves": True,
                "bumps": [[0, 0, 6, 9, 8]],
            },
            {"type": "cylinder", "center": [-70, 0, 800], "radius": 10, "height": 200},  # static post
            {"type": "plane", "center": [0, 0, 840], "size": [900, 700], "color": [0.6, 0.6, 0.6]},
        ],
    }


def assert_same_frames(fast: VirtualRig, ref: VirtualRig, frames: int) -> None:
    assert fast._layer is not None and ref._layer is None  # the moving path, and the full one
    pats = [fast.prepare(p) for p in two_shot_patterns(fast.projector_size).images]
    before = None
    for k in range(frames):
        a, b = fast.render(pats[k % 2]), ref.render(pats[k % 2])
        assert np.array_equal(a, b), f"frame {k}: {(a != b).any(axis=2).sum()} pixels differ"
        ga, gb = fast.ground_truth, ref.ground_truth
        for f in GT_FIELDS:
            assert np.array_equal(getattr(ga, f), getattr(gb, f), equal_nan=True), f"frame {k}: ground truth {f}"
        if before is not None:
            assert not np.array_equal(ga.depth, before)  # it did move
        before = ga.depth.copy()


@pytest.mark.parametrize(
    ("scene", "motion"),
    [
        ("cube", {"motion_mm_per_frame": [6, -3, 4]}),
        ("face", {"motion_mm_per_frame": [8, 0, 0]}),  # the relief: the same march in both paths
        ("mixed", {"motion_mm_per_frame": [3, 2, -2]}),
        ("mixed", {"rotation_deg_per_frame": 5, "rotation_axis": [0.3, -1, 0.2], "motion_mm_per_frame": [1, 0, 0]}),
        ("turntable", {"motion_mm_per_frame": [2, 0, -3], "motion_bounce_frames": 2, "rotation_deg_per_frame": 11}),
        ("turntable", {"render_ahead": True}),  # each next frame composed on a background thread
    ],
)
def test_a_moving_frame_equals_the_full_precomputation_at_its_step(scene: str, motion: dict) -> None:
    def make(**kw) -> VirtualRig:
        s = parse_scene(mixed_scene(), Path("mixed.yaml")) if scene == "mixed" else load_scene(scene)
        return VirtualRig.from_scene(s, camera_size=SMALL, **motion, **kw)

    assert_same_frames(make(), make(reference_motion=True), frames=6)


def ellipsoid_depth(rays: np.ndarray, R: np.ndarray, c: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Z of the first hit of camera rays (N, 3) on the ellipsoid {x : |diag(1/axes) R^T (x - c)| = 1}."""
    A = R @ np.diag(1.0 / np.asarray(axes, float) ** 2) @ R.T
    qa = np.einsum("ij,jk,ik->i", rays, A, rays)
    qb = -2 * rays @ (A @ c)
    qc = c @ A @ c - 1.0
    disc = qb**2 - 4 * qa * qc
    with np.errstate(invalid="ignore"):
        t = (-qb - np.sqrt(disc)) / (2 * qa)
    return np.where(disc >= 0, t * rays[:, 2], np.inf)


def test_the_turntable_head_turns_about_its_vertical_axis() -> None:
    """The head's depth at frame n is that of the ellipsoid turned n * 2 degrees (analytic), wherever
    the head is what the camera sees; the nose and ears (also turning) only ever stand in front."""
    rig = VirtualRig.from_preset("turntable", camera_size=(320, 240), ideal=True)
    head = next(s for s in rig.scene.shapes if s.name == "head")
    p = np.array([0.0, 0.0, 770.0])  # the preset's rotation_center_mm; rotation_axis up
    white = np.full((768, 1024, 3), 255, np.uint8)
    depths = {}
    for n in range(46):
        rig.render(white)  # call n shows frame n
        if n not in (0, 17, 45):
            continue
        gt = rig.ground_truth
        Rm = rotation_matrix(np.array([0.0, -1.0, 0.0]), 2.0 * n)
        z = ellipsoid_depth(rig._rays, Rm @ head.R, Rm @ (head.c - p) + p, head.semi_axes).reshape(gt.depth.shape)
        on = np.isfinite(z)
        same = on & (np.abs(gt.depth - z) < 1e-3)
        assert on.sum() > 5000 and same.sum() > 0.9 * on.sum()
        assert np.all(gt.depth[on] <= z[on] + 1e-3)  # nothing of the scene behind the head shows through it
        depths[n] = gt.depth.copy()
    assert not np.array_equal(depths[0], depths[45]) and not np.array_equal(depths[17], depths[45])


def test_translation_bounces_back_after_the_given_frames() -> None:
    data = {
        "description": "a moving ball",
        "depth_range_mm": [600, 900],
        "objects": [
            {"type": "sphere", "center": [0, 0, 700], "radius": 40, "moves": True},
            {"type": "plane", "center": [0, 0, 850], "size": [900, 700]},
        ],
    }
    r = VirtualRig.from_scene(
        parse_scene(data, Path("ball.yaml")),
        ideal=True,
        camera_size=SMALL,
        motion_mm_per_frame=[0, 0, 5],
        motion_bounce_frames=2,
    )
    nearest = []
    for _ in range(7):
        r.render(None)
        d = r.ground_truth.depth
        nearest.append(float(d[d > 0].min()))
    assert np.allclose(np.array(nearest) - nearest[0], [0, 5, 10, 5, 0, 5, 10], atol=0.05)


def test_ideal_keeps_the_scenes_motion_and_a_still_override_stops_it() -> None:
    turning = VirtualRig.from_preset("turntable", camera_size=SMALL, ideal=True)
    assert turning.options.rotation_deg_per_frame == 2.0 and turning.options.noise is False
    still = VirtualRig.from_preset("turntable", camera_size=SMALL, rotation_deg_per_frame=0)
    assert still._layer is None  # nothing moves: the still scene's path
    d0 = still.ground_truth.depth.copy()
    still.render(None)
    still.render(None)
    assert np.array_equal(still.ground_truth.depth, d0)


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("rotation_deg_per_frame", "fast"),
        ("rotation_deg_per_frame", float("nan")),
        ("rotation_axis", [0, 0, 0]),
        ("rotation_axis", [0, 1]),
        ("rotation_center_mm", [0, "x", 700]),
        ("motion_mm_per_frame", [1, 2]),
        ("motion_bounce_frames", -1),
        ("motion_bounce_frames", 2.5),
        ("render_ahead", "yes"),
    ],
)
def test_bad_motion_options_are_named_in_one_line(option: str, value: object) -> None:
    with pytest.raises(InputError) as info:
        VirtualRig.from_preset("turntable", camera_size=SMALL, **{option: value})
    msg = str(info.value)
    assert f"'{option}'" in msg and "turntable.yaml" in msg and "\n" not in msg


def test_a_sim_config_with_a_bad_motion_effect_names_the_key(tmp_path: Path) -> None:
    from app.config import load_config
    from drivers.sim.devices import bench_from_config

    cfg = tmp_path / "sim.yaml"
    cfg.write_text("sim:\n  scene: turntable\n  camera_size: [160, 120]\n  effects: {rotation_axis: [0, 0, 0]}\n")
    with pytest.raises(InputError, match="'rotation_axis'"):
        bench_from_config(load_config(cfg))


@pytest.fixture(scope="module")
def turntable_session():
    """config/sim_turntable.yaml at 320x240, with its decoder built once (compiled on a cold cache)."""
    from app.session import build_session

    config = Path(__file__).resolve().parents[3] / "config" / "sim_turntable.yaml"
    session = build_session(config, sim_overrides={"camera_size": [320, 240]})
    return session, session.processor()


def test_the_turntable_config_runs_a_live_session_on_the_moving_scene(turntable_session) -> None:
    """The live pipeline decodes the turning bust; each set's depth agrees with the rig's truth of
    its newest frame where both have depth (the bust turns 2 degrees between the two frames)."""
    from app.live_pipeline import LivePipeline

    session, processor = turntable_session
    rig = session.sim.rig
    assert rig.scene.name == "turntable" and rig.moving and rig._layer is not None
    truths: dict[int, np.ndarray] = {}

    def keep_truth(frame) -> None:  # the acquisition thread: the rig has just rendered this frame
        truths[frame.frame_id] = rig.ground_truth.depth.copy()

    pipe = LivePipeline(lambda: session.make_loop(timeout_s=3.0), processor, max_frames=24, on_frame=keep_truth)
    pipe.start()
    pipe.wait()
    assert pipe.error is None and pipe.figures()["depth_maps"] >= 3
    res = pipe.latest
    gt = truths[max(res.frameset.frame_ids)]
    both = (res.depth > 0) & (gt > 0)
    assert both.mean() > 0.3
    assert np.median(np.abs(res.depth[both] - gt[both])) < 1.0
    assert rig.frame_index >= 24 and not np.array_equal(truths[min(truths)], gt)


def test_face_far_has_narrower_stripes_and_less_light() -> None:
    def stripes_and_white(name: str) -> tuple[float, float]:
        rig = VirtualRig.from_preset(name, noise=False)
        gt = rig.ground_truth
        g = np.abs(np.gradient(gt.column.astype(np.float64), axis=1))
        face = gt.lit & (gt.depth < gt.depth[gt.visible].max() - 20) & np.isfinite(g) & (g > 0)
        white = rig.render(np.full((768, 1024, 3), 255, np.uint8))[..., 1]
        return float(np.median(1 / g[face])), float(white[face].mean())

    near_w, near_white = stripes_and_white("face")
    far_w, far_white = stripes_and_white("face_far")
    assert 2.0 < near_w < 2.3 and 1.6 < far_w < 2.0
    assert far_white < 0.8 * near_white  # inverse square from the projector (camera gamma 1.8 on top)
