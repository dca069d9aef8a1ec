"""Frame dump format v1: round trip, crash tolerance, paths that escape, refusal to overwrite."""

from __future__ import annotations

import numpy as np
import pytest

from core.calibration import Calibration
from core.dump import DumpWriter, read_dump
from core.errors import InputError
from core.patterns import two_shot_patterns


def small_calibration() -> Calibration:
    K = [[500, 0, 31.5], [0, 500, 23.5], [0, 0, 1]]
    return Calibration((64, 48), K, [0] * 5, (128, 96), K, [0] * 5, np.eye(3), [-100, 0, 0], color_mixing=np.eye(3))


def write_dump(folder, n=5):
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8) for _ in range(n)]
    with DumpWriter(folder, two_shot_patterns((128, 96)), small_calibration(), depth_range_mm=(300, 900)) as w:
        for i, f in enumerate(frames):
            w.add(f, pattern=i % 2, frame_id=10 + i, timestamp_ns=1000 * i)
    return frames


def test_round_trip(tmp_path):
    frames = write_dump(tmp_path / "d")
    d = read_dump(tmp_path / "d")
    assert d.scheme == "two-shot" and len(d.frames) == 5 and d.dropped_tail == 0
    assert [f.pattern for f in d.frames] == [0, 1, 0, 1, 0]
    assert [f.frame_id for f in d.frames] == [10, 11, 12, 13, 14]
    assert d.depth_range_mm() == (300, 900)
    for i, f in enumerate(frames):
        assert np.array_equal(d.load_frame(i), f)
    assert d.calibration().camera_size == (64, 48)
    assert len(d.patterns()) == 2 and d.patterns_meta()["period"] == 256


def test_sixteen_bit_frames_round_trip(tmp_path):
    img = (np.arange(48 * 64 * 3).reshape(48, 64, 3) * 7).astype(np.uint16)
    with DumpWriter(tmp_path / "d", two_shot_patterns((128, 96))) as w:
        w.add(img, 0, 1, 5)
    back = read_dump(tmp_path / "d").load_frame(0)
    assert back.dtype == np.uint16 and np.array_equal(back, img)


def test_half_written_last_line_is_dropped(tmp_path):
    write_dump(tmp_path / "d")
    idx = tmp_path / "d" / "dump.yaml"
    text = idx.read_text()
    idx.write_text(text[:-25])  # a writer killed in the middle of the last entry
    d = read_dump(tmp_path / "d")
    assert len(d.frames) == 4
    assert np.array_equal(d.load_frame(3), read_dump(tmp_path / "d").load_frame(3))


def test_missing_last_frame_file_is_tolerated_but_missing_middle_is_an_error(tmp_path):
    write_dump(tmp_path / "d")
    (tmp_path / "d" / "frames" / "000004.png").unlink()
    d = read_dump(tmp_path / "d")
    assert len(d.frames) == 4 and d.dropped_tail == 1
    (tmp_path / "d" / "frames" / "000001.png").unlink()
    with pytest.raises(InputError, match=r"000001\.png"):
        read_dump(tmp_path / "d")


def test_refuses_to_overwrite(tmp_path):
    write_dump(tmp_path / "d")
    with pytest.raises(InputError, match="never overwritten"):
        DumpWriter(tmp_path / "d", two_shot_patterns((128, 96)))
    assert len(read_dump(tmp_path / "d").frames) == 5


def test_timestamps_must_not_go_back(tmp_path):
    with DumpWriter(tmp_path / "d", two_shot_patterns((128, 96))) as w:
        w.add(np.zeros((4, 4, 3), np.uint8), 0, 1, 100)
        with pytest.raises(ValueError, match="back in time"):
            w.add(np.zeros((4, 4, 3), np.uint8), 1, 2, 50)


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda t: t.replace("frames/000002.png", "../../etc/passwd"), "leaves the dump folder"),
        (lambda t: t.replace("frames/000002.png", "/etc/passwd"), "leaves the dump folder"),
        (lambda t: t.replace("patterns: patterns", "patterns: ../x"), "leaves the dump folder"),
        (lambda t: t.replace("calibration: calibration.yaml", "calibration: /tmp/c.yaml"), "leaves the dump folder"),
        (lambda t: t.replace("format: slscan-dump", "format: other"), "format"),
        (lambda t: t.replace("version: 1", "version: 7"), "version"),
        (lambda t: t.replace("depth_range_mm:\n- 300.0\n- 900.0", "depth_range_mm: [900, 300]"), "depth_range_mm"),
        (lambda t: t.replace("frame_id: 12", "frame_id: x"), "frames\\[2\\]"),
        (lambda t: "{{{" + t, "not valid YAML"),
        (lambda t: "- a list\n", "mapping"),
    ],
)
def test_bad_dump_yaml_names_the_problem(tmp_path, edit, words):
    write_dump(tmp_path / "d")
    idx = tmp_path / "d" / "dump.yaml"
    new = edit(idx.read_text())
    assert new != idx.read_text()
    idx.write_text(new)
    with pytest.raises(InputError, match=words):
        read_dump(tmp_path / "d")


def test_not_a_dump(tmp_path):
    with pytest.raises(InputError, match="not a frame dump"):
        read_dump(tmp_path)
