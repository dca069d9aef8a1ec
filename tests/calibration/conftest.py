"""Shared fixtures: virtual rigs with a calibration board."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.auto import make_rig, rig_board
from calibration.poses import plan_poses

_RIGS: dict[tuple, object] = {}


def rig_for(scene: str, **overrides: object):
    """One rig per scene and overrides per session (construction costs seconds); tests pose its board."""
    key = (scene, *sorted(overrides.items()))
    if key not in _RIGS:
        _RIGS[key] = make_rig(scene, **overrides)
    return _RIGS[key]


@pytest.fixture(scope="session")
def board_rig():
    """rig_for as a fixture: board_rig("checkerboard", exposure=2.0)."""
    return rig_for


@pytest.fixture(scope="session")
def board_rig_views():
    """scene -> (board, [(white camera image, true corner pixels), ...]) for two tilted poses."""
    cache: dict[str, tuple] = {}

    def get(scene: str):
        if scene not in cache:
            rig = rig_for(scene)
            board = rig_board(rig)
            white = rig.prepare(np.full((rig.projector_size[1], rig.projector_size[0], 3), 255, np.uint8))
            views = []
            for rvec, tvec in plan_poses(board, rig.calibration, 2, seed=3):
                rig.set_board_pose(rvec, tvec)
                views.append((rig.render(white), rig.board_corners_image()))
            cache[scene] = (board, views)
        return cache[scene]

    return get
