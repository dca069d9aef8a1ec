"""The depth stream's message format (core/depth_message.py): round trips, and messages that do not match their
header refused in one line."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from core.calibration import Calibration
from core.depth_message import FORMAT, calibration_digest, decode_message, encode_end, encode_scan
from core.errors import InputError


def parts_of(message) -> list[bytes]:
    return [bytes(p) for p in message]  # as a receiver gets them


def test_a_scan_round_trips_with_and_without_points():
    rng = np.random.default_rng(0)
    depth = np.where(rng.random((6, 8)) > 0.5, rng.uniform(300, 900, (6, 8)), 0).astype(np.float32)
    msg = decode_message(parts_of(encode_scan({"sequence": 3, "frame_ids": [5, 4]}, depth)))
    assert np.array_equal(msg.depth, depth) and msg.points is None and not msg.is_end
    h = msg.header
    fixed = (h["format"], h["width"], h["height"], h["dtype"], h["units"], h["none"])
    assert fixed == (FORMAT, 8, 6, "float32", "mm", 0)
    assert h["sequence"] == 3 and h["frame_ids"] == [5, 4] and h["parts"] == ["depth"]
    pts = rng.uniform(-100, 100, (int((depth > 0).sum()), 3)).astype(np.float32)
    rgb = rng.integers(0, 256, pts.shape, dtype=np.uint8)
    msg = decode_message(parts_of(encode_scan({}, depth, pts, rgb)))
    assert np.array_equal(msg.points, pts) and np.array_equal(msg.colors, rgb) and msg.header["points"] == len(pts)
    end = decode_message(parts_of(encode_end({"sequence": 9})))
    assert end.is_end and end.depth is None and end.header["sequence"] == 9


def _header(**change) -> bytes:
    h = {"format": FORMAT, "kind": "scan", "width": 4, "height": 2, "dtype": "float32", "parts": ["depth"], **change}
    return json.dumps(h).encode()


DEPTH = np.zeros((2, 4), np.float32).tobytes()
BAD = {
    "not json": ([b"\xff{", DEPTH], "not JSON"),
    "another format": ([_header(format="other/2"), DEPTH], "format 'other/2'"),
    "short depth": ([_header(), DEPTH[:-4]], "depth has 28 bytes"),
    "missing part": ([_header()], "0 array part(s)"),
    "another dtype": ([_header(dtype="float64"), DEPTH], "are not this format's"),
    "no sizes": ([json.dumps({"format": FORMAT, "kind": "scan"}).encode(), DEPTH], "lacks width"),
    "empty": ([], "empty message"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_a_message_that_does_not_match_its_header_is_one_line(name):
    parts, expected = BAD[name]
    with pytest.raises(InputError, match=re.escape(expected)) as info:
        decode_message(parts, "tcp://x:1")
    assert "\n" not in str(info.value) and str(info.value).startswith("tcp://x:1: ")


def test_the_calibration_digest_is_of_the_numbers_not_the_file(tmp_path):
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    P = np.array([[1200.0, 0, 512], [0, 1200, 384], [0, 0, 1]])
    cal = Calibration((640, 480), K, np.zeros(5), (1024, 768), P, np.zeros(5), np.eye(3), np.array([-150.0, 0, 0]))
    cal.save(tmp_path / "a.yml")
    again = Calibration.load(tmp_path / "a.yml")
    assert calibration_digest(again) == calibration_digest(cal) and len(calibration_digest(cal)) == 64
    again.T = again.T + np.array([0.0, 0.0, 1e-6])
    assert calibration_digest(again) != calibration_digest(cal)
