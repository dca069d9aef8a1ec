"""The wizard's bookkeeping on the virtual rig: per-pose figures at once, undo, coverage, tilt hints."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.auto import fronto_pose, rig_board
from calibration.capture import CaptureWriter, open_capture
from calibration.poses import plan_poses
from calibration.solve import MIN_POSES
from calibration.wizard_state import WizardState, cells, overlay, tilt_direction
from core.patterns import graycode_patterns


def test_tilt_directions_and_cells():
    assert tilt_direction(np.zeros(3)) == (0.0, [])
    t, dirs = tilt_direction(np.array([0.0, np.deg2rad(30), 0.0]))
    assert abs(t - 30) < 1e-6 and len(dirs) == 1
    _, dirs2 = tilt_direction(np.array([0.0, -np.deg2rad(30), 0.0]))
    assert dirs2 != dirs and {*dirs, *dirs2} == {"left", "right"}
    _, up = tilt_direction(np.array([np.deg2rad(25), 0.0, 0.0]))
    assert up[0] in ("up", "down")
    m = cells(np.array([[0, 0], [320, 0], [320, 240], [0, 240]], float), (640, 480))
    assert m.shape == (6, 8) and m[:3, :4].all() and not m[3:, :].any() and not m[:, 4:].any()


@pytest.mark.slow
def test_poses_added_undone_and_judged(tmp_path, board_rig):
    """Ground-truth projector maps stand in for the decoder: this tests the bookkeeping."""
    rig = board_rig("checkerboard", supersample=2)  # bookkeeping, not accuracy: a cheaper board render
    board = rig_board(rig)
    pats = graycode_patterns(rig.projector_size)
    meta = {"size": list(pats.size), **pats.params}
    white = rig.prepare(pats.images[0])
    writer = CaptureWriter(tmp_path / "cap", board, pats)
    state = WizardState(board, rig.camera_size, rig.projector_size, writer=None, guess_focal_px=2200.0)

    def gt_decode(frames, meta):
        return rig.ground_truth.column, rig.ground_truth.row

    def frames_now():
        img = rig.render(white)
        return [img] * len(pats)

    assert state.missing_tilts() == ["left", "right", "up", "down"]
    # a pose with the board out of view: said, not kept, the session goes on
    rvec, tvec = fronto_pose(board, rig)
    rig.set_board_pose(rvec, tvec + np.array([120.0, 0, 0]))  # half of it out of view
    state.add_pose(frames_now(), meta, gt_decode)
    assert state.poses == [] and "no board found" in state.messages[-1]
    for i, (rvec, tvec) in enumerate(plan_poses(board, rig.calibration, MIN_POSES + 1, seed=7)):
        rig.set_board_pose(rvec, tvec)
        state.add_pose(frames_now(), meta, gt_decode)
        if i < MIN_POSES - 1:
            assert "error after" in state.messages[-1]
    assert len(state.poses) == MIN_POSES + 1
    assert "camera 0.0" in state.messages[-1] and "projector 0.0" in state.messages[-1]  # per-pose error at once
    err = state.pose_error(0)
    assert err is not None and err[0] < 0.1 and err[1] < 0.1
    assert state.camera_coverage().mean() > 0.3 and 0 < state.projector_coverage().mean() < 1
    assert len(state.missing_tilts()) < 4
    hints = "\n".join(state.hints())
    assert f"poses {MIN_POSES + 1} (minimum {MIN_POSES}" in hints
    state.undo()
    assert len(state.poses) == MIN_POSES and "pose_005 removed" in state.messages[-1]
    assert state.solution is not None and state.solution.passed
    for _ in range(MIN_POSES):
        state.undo()
    assert state.solution is None and state.poses == []
    # overlay draws corners in green on a copy
    img = rig.render(white)
    from calibration.board import detect

    det = detect(board, img)
    ov = overlay(img, det)
    assert ov is not img and (ov != img).any() and ov[..., 1].max() == 255
    # the writer keeps what the wizard keeps, and undo removes it
    writer.add_pose(frames_now())
    writer.add_pose(frames_now())
    assert writer.remove_last_pose() == "pose_001"
    assert open_capture(tmp_path / "cap").poses == ["pose_000"]
