"""Board description YAML: round trip, every wrong field named; detection on the virtual rig."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from calibration.board import Board, board_from_dict, detect, load_board
from core.errors import InputError

GOOD = {"type": "checkerboard", "rows": 7, "cols": 10, "square_mm": 12.0}
CHARUCO = {"type": "charuco", "rows": 8, "cols": 11, "square_mm": 12.0, "marker_mm": 9.0, "dictionary": "DICT_5X5_100"}


@pytest.mark.parametrize("spec", [GOOD, CHARUCO])
def test_round_trip(tmp_path, spec):
    b = board_from_dict(spec)
    b.save(tmp_path / "board.yaml")
    assert load_board(tmp_path / "board.yaml") == b
    assert yaml.safe_load((tmp_path / "board.yaml").read_text()) == spec


def test_object_points():
    b = board_from_dict(GOOD)
    pts = b.object_points()
    assert pts.shape == (70, 3)
    assert np.allclose(pts[1], [12, 0, 0]) and np.allclose(pts[10], [0, 12, 0]) and np.allclose(pts[-1], [108, 72, 0])
    c = board_from_dict(CHARUCO)
    assert c.object_points().shape == (70, 3)  # (11-1) x (8-1) inner corners
    assert np.allclose(c.object_points()[0], [12, 12, 0])  # OpenCV's ChArUco frame


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"type": "circles"}, "field 'type'"),
        ({"rows": 1}, "field 'rows'"),
        ({"cols": "ten"}, "field 'cols'"),
        ({"rows": 10}, "rows and cols are both 10"),
        ({"square_mm": -3}, "field 'square_mm'"),
        ({"square_mm": None}, "field 'square_mm'"),
        ({"colour": "red"}, "unknown field 'colour'"),
        # keys YAML reads as null or a number beside a misspelt name: named, never compared with it
        ({None: 5, "colour": "red"}, "unknown field 'None'"),
        ({3: "x", "colour": "red"}, "unknown field '3'"),
    ],
)
def test_wrong_checkerboard_fields(tmp_path, change, words):
    spec = {**GOOD, **change}
    (tmp_path / "board.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    with pytest.raises(InputError, match=words) as e:
        load_board(tmp_path / "board.yaml")
    assert "board.yaml" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"dictionary": "DICT_9X9_1"}, "field 'dictionary'"),
        ({"marker_mm": 12.0}, "field 'marker_mm'"),
        ({"marker_mm": None}, "field 'marker_mm'"),
        ({"dictionary": "DICT_4X4_50", "rows": 12, "cols": 12}, "needs 72 markers"),
    ],
)
def test_wrong_charuco_fields(change, words):
    with pytest.raises(InputError, match=words):
        board_from_dict({**CHARUCO, **change}, "b.yaml")


def test_missing_and_garbage(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_board(tmp_path / "nope.yaml")
    (tmp_path / "b.yaml").write_text("type: [checkerboard")
    with pytest.raises(InputError, match="not valid YAML"):
        load_board(tmp_path / "b.yaml")
    (tmp_path / "b.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(InputError, match="expected a mapping"):
        load_board(tmp_path / "b.yaml")
    spec = dict(GOOD)
    del spec["rows"]
    with pytest.raises(InputError, match="missing field 'rows'"):
        board_from_dict(spec)


# Measured: checkerboard (findChessboardCornersSB, ACCURACY) ~0.036 px RMS; ChArUco with the saddle
# refinement ~0.041 px RMS (OpenCV's own ChArUco corners ~0.09 px).
@pytest.mark.parametrize(("scene", "limit"), [("checkerboard", 0.06), ("charuco", 0.07)])
def test_detection_on_the_rig_matches_true_corners(scene, limit, board_rig_views):
    """Sub-pixel corners against the rig's true corner positions (noise, blur, gamma on)."""
    board, views = board_rig_views(scene)
    for white, true in views:
        det = detect(board, white)
        assert det is not None
        err = np.linalg.norm(det.corners - true[det.ids], axis=1)
        assert len(det) >= 0.8 * board.n_corners
        assert np.sqrt((err**2).mean()) < limit, err.max()


def test_no_board_in_a_blank_image():
    b = Board("checkerboard", 7, 10, 12.0)
    assert detect(b, np.full((480, 640, 3), 128, np.uint8)) is None
