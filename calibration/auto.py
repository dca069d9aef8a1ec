"""`slscan calibrate --auto`: the virtual rig poses its own board and films the Gray code.

Writes an ordinary calibration capture (board.yaml + pose_NNN/ dumps + response/), so
`slscan calibrate --from` repeats the solve, and each pose dump carries the rig's true
calibration (as every dump of the virtual rig does) for scoring. Headless.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from calibration.board import Board, board_from_dict
from calibration.capture import CaptureWriter
from calibration.poses import plan_poses
from calibration.response import level_image, level_plan
from core.errors import InputError
from core.patterns import graycode_patterns

DEFAULT_SCENE = "checkerboard"


def rig_board(rig) -> Board:
    """The board.yaml description of the rig scene's board."""
    if rig.board is None:
        raise InputError(f"scene {rig.scene.name!r} has no calibration board (use a board scene, e.g. checkerboard)")
    spec = rig.board.board_yaml()
    return board_from_dict(spec, f"scene {rig.scene.name!r}")


def make_rig(scene: str = DEFAULT_SCENE, **overrides: object):
    from drivers.sim.rig import VirtualRig  # lazy: the rig precomputes on construction

    return VirtualRig.from_preset(scene, **overrides)


def fronto_pose(board: Board, rig) -> tuple[np.ndarray, np.ndarray]:
    """The board facing the camera in the middle of the field, for the colour levels."""
    pts = board.object_points().astype(np.float64)
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    z = float(np.mean(rig.depth_range_mm))
    return np.zeros(3), np.array([0.0, 0.0, z]) - centre


def auto_capture(
    out: str | os.PathLike,
    n_poses: int,
    rig=None,
    scene: str = DEFAULT_SCENE,
    seed: int = 0,
    response: bool = True,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Pose the simulated board n_poses times (tilt variety), film the Gray code, write a capture."""
    if n_poses < 1:
        raise InputError(f"--poses {n_poses}: need at least 1 pose")
    rig = rig if rig is not None else make_rig(scene)
    board = rig_board(rig)
    truth = rig.calibration
    try:
        poses = plan_poses(board, truth, n_poses, seed=seed)
    except RuntimeError as exc:
        raise InputError(f"scene {rig.scene.name!r}: {exc}") from None
    patterns = graycode_patterns(rig.projector_size)
    prepared = [rig.prepare(img) for img in patterns.images]
    writer = CaptureWriter(out, board, patterns)
    for i, (rvec, tvec) in enumerate(poses):
        rig.set_board_pose(rvec, tvec)
        frames = [rig.render(p) for p in prepared]
        name = writer.add_pose(frames, calibration=truth, calibration_is_truth=True)
        if progress:
            tilt = np.degrees(np.linalg.norm(rvec))
            progress(f"{name}: board at {tvec[2]:.0f} mm, tilted {tilt:.0f} deg ({i + 1}/{n_poses})")
    if response:
        rig.set_board_pose(*fronto_pose(board, rig))
        levels = [(ch, lv, rig.render(level_image(rig.projector_size, ch, lv))) for ch, lv in level_plan()]
        writer.write_response(levels, camera_gamma=rig.options.camera_gamma)
        if progress:
            progress(f"response: {len(levels)} flat colour levels")
    return Path(out)
