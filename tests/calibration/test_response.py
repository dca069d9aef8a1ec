"""Colour response on the virtual rig: its projector gamma and colour mixing recovered; warnings."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.auto import fronto_pose, rig_board
from calibration.response import level_image, level_plan, measure_response


def levels_on(rig):
    rig.set_board_pose(*fronto_pose(rig_board(rig), rig))
    return [(ch, lv, rig.render(level_image(rig.projector_size, ch, lv))) for ch, lv in level_plan()]


def test_recovers_the_rigs_known_response(board_rig):
    rig = board_rig("checkerboard")
    resp = measure_response(levels_on(rig), camera_gamma=rig.options.camera_gamma)
    assert resp.warnings == []
    # projector gamma 2.2 through a camera of gamma 1.8, with black level, ambient, crosstalk, noise
    assert resp.gamma == pytest.approx([rig.options.projector_gamma] * 3, rel=0.02)
    true = rig.calibration.color_mixing
    assert np.abs(resp.color_mixing - true).max() < 0.01
    # the off-diagonal leaks themselves within a few percent
    off = ~np.eye(3, dtype=bool)
    assert np.abs(resp.color_mixing[off] / true[off] - 1).max() < 0.05
    # each channel's curve against the rig's true projector light (black level removed), normalised
    true_curve = rig.projector_light(resp.levels) - rig.projector_light(0)
    for c in range(3):
        got = resp.curves[c] / resp.curves[c, -1]
        assert np.abs(got - true_curve / true_curve[-1]).max() < 0.02
    # curves rise monotonically from 0
    assert np.all(np.diff(resp.curves, axis=1) > 0) and np.all(resp.curves[:, 0] == 0)


@pytest.mark.parametrize(("exposure", "words"), [(3.0, "nearly saturated"), (0.04, "too dark")])
def test_warns_when_a_channel_is_saturated_or_dark(exposure, words, board_rig):
    rig = board_rig("checkerboard", exposure=exposure)
    resp = measure_response(levels_on(rig), camera_gamma=rig.options.camera_gamma)
    assert len(resp.warnings) == 3 and all(words in w for w in resp.warnings)
    assert "channel R" in resp.warnings[0]


def test_no_lit_surface_is_an_error():
    dark = [(ch, lv, np.zeros((48, 64, 3), np.uint8)) for ch, lv in level_plan()]
    with pytest.raises(ValueError, match="too few lit surface pixels"):
        measure_response(dark)
