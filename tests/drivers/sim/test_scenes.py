"""Scene presets: every one loads, fits its working volume, and bad scene files fail clearly."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from core.errors import InputError
from drivers.sim.optics import Geometry, project, undistort_normalized
from drivers.sim.rig import VirtualRig
from drivers.sim.scene import SceneError, list_presets, load_scene, parse_scene

PRESETS = [name for name, _ in list_presets()]
REQUIRED = {"plane", "face", "colour_panel", "cube", "cylinder", "steps", "checkerboard", "charuco"}


def test_the_presets_the_other_modules_rely_on_exist_and_describe_themselves() -> None:
    assert REQUIRED <= set(PRESETS)
    for name, desc in list_presets():
        assert desc and "\n" not in desc, name


@pytest.mark.parametrize("name", PRESETS)
def test_preset_working_volume_leaves_no_stripe_ambiguity_and_holds_the_scene(name: str) -> None:
    scene = load_scene(name)
    near, far = scene.depth_range_mm
    # along every camera ray the projector column moves less than one one-shot period (192 stripes)
    # between near and far, so the depth range picks the copy of a repeated sequence
    g = Geometry(**{k: tuple(v) if isinstance(v, list) else v for k, v in scene.geometry.items()})
    u, v = np.meshgrid(np.linspace(0, 639, 17), np.linspace(0, 479, 13))
    xy = undistort_normalized(
        np.stack([u.ravel(), v.ravel()], axis=1), g.camera_matrix(), np.array(g.camera_distortion)
    )
    rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    R, T = g.extrinsics()
    cols = [project(rays * z, g.projector_matrix(), np.array(g.projector_distortion), R, T)[:, 0] for z in (near, far)]
    assert np.abs(cols[0] - cols[1]).max() < 192
    rig = VirtualRig.from_scene(scene, camera_size=(160, 120))
    gt = rig.ground_truth
    assert gt.lit.mean() > 0.3
    assert near <= gt.depth[gt.visible].min() and gt.depth.max() <= far


def test_checkerboard_corners_are_detected_where_the_ground_truth_puts_them() -> None:
    rig = VirtualRig.from_preset("checkerboard")  # realistic: noise, blur, ambient
    white = np.full((768, 1024, 3), 255, np.uint8)
    for pose in (None, ([-0.3, 0.2, 0.0], [-60.0, -30.0, 650.0])):
        if pose is not None:
            rig.set_board_pose(np.array(pose[0]), np.array(pose[1]))
        grey = cv2.cvtColor(rig.render(white), cv2.COLOR_RGB2GRAY)
        found, corners = cv2.findChessboardCornersSB(grey, (10, 7), flags=cv2.CALIB_CB_ACCURACY)
        assert found
        corners = corners.reshape(-1, 2)
        truth = rig.board_corners_image()
        err = min(np.linalg.norm(c - truth, axis=1).mean() for c in (corners, corners[::-1]))
        assert err < 0.1  # anti-aliased board: sub-pixel corners
        gt = rig.ground_truth
        assert abs(gt.depth[gt.visible].mean() - (pose[1][2] if pose else 720)) < 60


def test_charuco_markers_decode_with_opencv_and_corners_match_the_board_frame() -> None:
    rig = VirtualRig.from_preset("charuco", ideal=True)
    grey = cv2.cvtColor(rig.render(np.full((768, 1024, 3), 255, np.uint8)), cv2.COLOR_RGB2GRAY)
    corners, ids, _, marker_ids = cv2.aruco.CharucoDetector(rig.board.texture.board()).detectBoard(grey)
    assert ids is not None and len(ids) >= 60 and len(marker_ids) >= 40
    truth = rig.board_corners_image()[ids.ravel()]
    assert np.linalg.norm(corners.reshape(-1, 2) - truth, axis=1).mean() < 0.25


def test_board_yaml_has_the_documented_fields() -> None:
    board = load_scene("charuco").board
    assert board.board_yaml() == {
        "type": "charuco",
        "rows": 8,
        "cols": 11,
        "square_mm": 12.0,
        "marker_mm": 9.0,
        "dictionary": "DICT_5X5_100",
    }
    assert load_scene("checkerboard").board.board_yaml() == {
        "type": "checkerboard",
        "rows": 7,
        "cols": 10,
        "square_mm": 12.0,
    }
    assert load_scene("checkerboard").board.object_points().shape == (70, 3)


def test_board_pose_needs_a_board_and_a_pose_in_front() -> None:
    rig = VirtualRig.from_preset("plane", camera_size=(160, 120))
    with pytest.raises(InputError, match="no calibration board"):
        rig.set_board_pose(np.zeros(3), np.array([0, 0, 700.0]))
    board = VirtualRig.from_preset("checkerboard", camera_size=(160, 120))
    with pytest.raises(InputError, match="not in front"):
        board.set_board_pose(np.zeros(3), np.array([0, 0, -700.0]))
    before = board.board_corners_image()
    with pytest.raises(InputError, match="camera sees no surface"):
        board.set_board_pose(np.zeros(3), np.array([3000.0, 0, 700.0]))  # out of view
    assert np.array_equal(board.board_corners_image(), before)  # the previous pose stays
    assert board.ground_truth.lit.any() and board.render(None).any()


BASE = {
    "description": "test",
    "depth_range_mm": [600, 900],
    "objects": [{"type": "sphere", "center": [0, 0, 700], "radius": 40}],
}


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d.pop("description"), "description"),
        (lambda d: d.pop("depth_range_mm"), "depth_range_mm"),
        (lambda d: d.pop("objects"), "objects"),
        (lambda d: d["objects"][0].pop("radius"), "objects[0].radius"),
        (lambda d: d["objects"][0].pop("center"), "objects[0].center"),
        (lambda d: d["objects"][0].pop("type"), "objects[0].type"),
        (lambda d: d["objects"][0].update(type="torus"), "objects[0].type"),
        (lambda d: d["objects"][0].update(color=[2, 0, 0]), "objects[0].color"),
        (lambda d: d["objects"][0].update(radius=-1), "objects[0].radius"),
        (lambda d: d.update(depth_range_mm=[900, 600]), "depth_range_mm"),
        (lambda d: d.update(rig={"warp_drive": 1}), "rig.warp_drive"),
        (lambda d: d["objects"].append({"type": "ellipsoid", "center": [0, 0, 700]}), "objects[1].semi_axes"),
        (
            lambda d: d["objects"].append({"type": "ellipsoid", "center": [0, 0, 700], "semi_axes": [1, 2]}),
            "objects[1].semi_axes",
        ),
        (
            lambda d: d["objects"].append({"type": "board", "board": {"type": "checkerboard", "rows": 7}, "pose": {}}),
            "objects[1].board.cols",
        ),
    ],
)
def test_bad_scene_fields_are_named(edit, field: str) -> None:
    import copy

    data = copy.deepcopy(BASE)
    edit(data)
    with pytest.raises(SceneError) as info:
        parse_scene(data, Path("bad.yaml"))
    msg = str(info.value)
    assert "bad.yaml" in msg and f"'{field}'" in msg and "\n" not in msg


@pytest.mark.parametrize(
    ("overrides", "words"),
    [
        ({"projector_position_mm": (0.0, 0.0, 0.0)}, "no baseline"),
        ({"camera_size": (0, 480)}, "camera_size"),
        ({"camera_focal_px": -5.0}, "camera_focal_px"),
        ({"projector_target_mm": (0.0, 0.0, -500.0)}, "behind the camera"),
        ({"bit_depth": 10}, "bit_depth"),
        ({"warp": 1}, "unknown option"),
    ],
)
def test_impossible_set_ups_are_refused(overrides: dict, words: str) -> None:
    with pytest.raises(InputError, match=words):
        VirtualRig.from_preset("plane", **{"camera_size": (160, 120), **overrides})


def test_a_scene_the_camera_or_projector_cannot_see_is_refused() -> None:
    behind = {**BASE, "objects": [{"type": "sphere", "center": [0, 0, -700], "radius": 40}]}
    with pytest.raises(InputError, match="camera sees no surface"):
        VirtualRig.from_scene(parse_scene(behind, Path("behind.yaml")), camera_size=(160, 120))
    away = parse_scene(BASE, Path("away.yaml"))
    with pytest.raises(InputError, match="lights nothing"):
        VirtualRig.from_scene(away, camera_size=(160, 120), projector_target_mm=(2000.0, 0.0, 100.0))
