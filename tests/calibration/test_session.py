"""One pose through detection, Gray-code decoding and corner mapping: the reasons a pose gives nothing."""

from __future__ import annotations

import numpy as np

from calibration.board import Board
from calibration.capture import PoseFrames
from calibration.session import observe_pose
from core.patterns import graycode_patterns


def _meta(size=(1024, 768)):
    pats = graycode_patterns(size)
    return pats, {"size": list(pats.size), **pats.params}


def test_projector_that_never_switched_is_undecodable(board_rig_views):
    board, views = board_rig_views("checkerboard")
    white = views[0][0]
    pats, meta = _meta()
    r = observe_pose(board, PoseFrames("pose_007", [white] * len(pats), meta))
    assert r.observation is None
    assert r.rejected.reason.startswith("Gray code undecodable on the board: only 0 of 70 corners")
    assert r.corners_camera is not None and len(r.corners_camera) == 70


def test_no_board_in_view():
    pats, meta = _meta()
    grey = np.full((480, 640, 3), 90, np.uint8)
    r = observe_pose(Board("checkerboard", 7, 10, 12.0), PoseFrames("pose_001", [grey] * len(pats), meta))
    assert r.observation is None and r.rejected.name == "pose_001"
    assert "no board found in the white frame" in r.rejected.reason
