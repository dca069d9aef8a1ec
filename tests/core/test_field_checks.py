"""Fields checked by their type, range and relation where they are read: a value no rig or recording can have is
one line naming the file and the field, before any work is done on it."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from app.config import load_config
from app.session import build_session
from calibration.capture import read_levels, write_levels
from core.calibration import Calibration
from core.dump import DumpWriter, read_dump
from core.errors import InputError
from core.pattern_export import read_patterns_meta, write_patterns
from core.patterns import two_shot_patterns

K = [[400, 0, 15.5], [0, 400, 11.5], [0, 0, 1]]


def calibration(**changes) -> Calibration:
    fields = dict(
        camera_size=(32, 24),
        camera_matrix=np.array(K, float),
        camera_distortion=np.zeros(5),
        projector_size=(64, 48),
        projector_matrix=np.array(K, float),
        projector_distortion=np.zeros(5),
        R=np.eye(3),
        T=np.array([-80.0, 0, 0]),
    )
    fields.update(changes)
    return Calibration(**fields)


@pytest.fixture
def dump(tmp_path):
    folder = tmp_path / "dump"
    with DumpWriter(folder, two_shot_patterns((64, 48)), calibration()) as w:
        for i in range(3):
            w.add(np.full((24, 32, 3), 50 * i, np.uint8), i % 2, i + 1, 1000 * i)
    return folder


def edit(path, pattern, replacement):
    text = path.read_text()
    assert re.search(pattern, text), pattern
    path.write_text(re.sub(pattern, replacement, text, count=1))


@pytest.mark.parametrize(
    ("pattern", "replacement", "message"),
    [
        (r"frame_id: 1,", "frame_id: 1.5,", r"frames\[0\]\.frame_id must be a whole number, found 1\.5"),
        (r"frame_id: 1,", "frame_id: true,", r"frames\[0\]\.frame_id must be a whole number, found True"),
        (r"frame_id: 1,", "frame_id: -1,", r"frames\[0\]\.frame_id = -1 is out of range"),
        (r"frame_id: 1,", f"frame_id: {2**64},", r"frames\[0\]\.frame_id = 18446744073709551616 is out of range"),
        (r"frame_id: 3,", "frame_id: 2,", r"frames\[2\]\.frame_id 2 does not increase \(frames\[1\] has 2\)"),
        (r"timestamp_ns: 2000", "timestamp_ns: 500", r"frames\[2\]\.timestamp_ns goes back in time"),
        (r"pattern: 1,", "pattern: 1e3,", r"frames\[1\]\.pattern must be a whole number"),
    ],
)
def test_index_entries_are_whole_increasing_numbers(dump, pattern, replacement, message):
    edit(dump / "dump.yaml", pattern, replacement)
    with pytest.raises(InputError, match=rf"dump\.yaml: {message}"):
        read_dump(dump)


def test_the_writer_refuses_ids_the_reader_would_refuse(tmp_path):
    with DumpWriter(tmp_path / "d", two_shot_patterns((64, 48))) as w:
        w.add(np.zeros((24, 32, 3), np.uint8), 0, 5, 0)
        with pytest.raises(ValueError, match="does not increase"):
            w.add(np.zeros((24, 32, 3), np.uint8), 1, 5, 10)
        with pytest.raises(ValueError, match="outside"):
            w.add(np.zeros((24, 32, 3), np.uint8), 1, 2**63, 10)
    assert [r.frame_id for r in read_dump(tmp_path / "d").frames] == [5]


def test_a_greyscale_frame_in_a_colour_dump_is_refused_naming_it(dump):
    frame = dump / "frames" / "000001.png"
    cv2.imwrite(str(frame), np.full((24, 32), 90, np.uint8))
    d = read_dump(dump)
    d.load_frame(0)
    with pytest.raises(InputError, match=rf"{re.escape(str(frame))}: a single-channel image where a colour frame"):
        d.load_frame(1)


@pytest.mark.parametrize(
    ("changes", "field", "message"),
    [
        ({"camera_matrix": np.array([[400, 0, 15.5], [1e9, 400, 11.5], [0, 0, 1]])}, "camera_matrix", "upper-tri"),
        ({"projector_matrix": np.array([[1e-300, 0, 30], [0, 400, 20], [0, 0, 1]])}, "projector_matrix", "focal"),
        ({"camera_matrix": np.array([[4e5, 0, 15.5], [0, 4e5, 11.5], [0, 0, 1]])}, "camera_matrix", "focal"),
        ({"camera_matrix": np.array([[400, 0, 15.5], [0, 40, 11.5], [0, 0, 1]])}, "camera_matrix", "5:1"),
        ({"camera_matrix": np.array([[400, 0, 900], [0, 400, 11.5], [0, 0, 1]])}, "camera_matrix", "principal"),
        ({"camera_distortion": np.array([1e12, 0, 0, 0, 0])}, "camera_distortion", "implausible"),
        ({"projector_distortion": np.array([0, 0, 3.0, 0, 0])}, "projector_distortion", "implausible"),
    ],
)
def test_intrinsics_no_lens_has_are_refused_naming_the_field(tmp_path, changes, field, message):
    path = tmp_path / "cal.yaml"
    # (the constructor does not check: a solver's result is checked by its caller, a file when it is read)
    calibration(**changes).save(path)
    with pytest.raises(InputError, match=rf"cal\.yaml: field '{field}' .*{re.escape(message)}"):
        Calibration.load(path)


def test_a_real_wide_angle_calibration_is_accepted(tmp_path):
    # a 640x480 camera behind a 120-degree lens with strong barrel distortion, a DLP with 2:1 pixels
    cal = calibration(
        camera_size=(640, 480),
        camera_matrix=np.array([[185.0, 0.3, 322.0], [0, 186.0, 241.0], [0, 0, 1]]),
        camera_distortion=np.array([-0.38, 0.17, 0.001, -0.002, -0.04]),
        projector_size=(912, 1140),
        projector_matrix=np.array([[1400.0, 0, 456.0], [0, 2800.0, 1140.0], [0, 0, 1]]),
    )
    path = tmp_path / "cal.yaml"
    cal.save(path)
    assert Calibration.load(path).camera_size == (640, 480)


@pytest.mark.parametrize(
    ("pattern", "replacement", "message"),
    [
        (r"period: 256", "period: 100", "field 'period' is 100 but the sequence has 256 stripes"),
        (r"images: \[frame1.png, frame2.png\]", "images: [frame1.png]", "field 'images' lists 1 image\\(s\\)"),
        (r"stripe_width: 1", "stripe_width: 1000000", "field 'stripe_width' 1000000 is too wide"),
    ],
)
def test_a_pattern_export_must_agree_with_its_sequence(tmp_path, pattern, replacement, message):
    write_patterns(two_shot_patterns((1024, 8)), tmp_path)
    edit(tmp_path / "patterns.yaml", pattern, replacement)
    with pytest.raises(InputError, match=rf"patterns\.yaml: {message}"):
        read_patterns_meta(tmp_path)


def test_config_numbers_are_not_booleans_and_depth_ranges_are_numbers(tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("capture:\n  rate_hz: true\n")
    with pytest.raises(InputError, match=r"cfg\.yaml: key 'capture\.rate_hz' must be int or float, found True"):
        build_session(load_config(cfg))
    cfg.write_text("depth_range_mm: ['600', 900]\n")
    with pytest.raises(InputError, match=r"cfg\.yaml: key 'depth_range_mm' must be \[near, far\] with finite"):
        build_session(load_config(cfg))


def test_calibration_levels_are_0_to_255_and_stay_inside(tmp_path):
    folder = tmp_path / "levels"
    write_levels(folder, [("G", 128, np.zeros((4, 6, 3), np.uint8))])
    edit(folder / "levels.yaml", r"level: 128", "level: 4096")
    with pytest.raises(InputError, match=r"levels\.yaml: frames\[0\] needs file, channel \(R, G or B\) and level"):
        read_levels(folder)
    edit(folder / "levels.yaml", r"level: 4096", "level: 128")
    outside = tmp_path / "elsewhere.png"
    (folder / "000_G_128.png").rename(outside)
    (folder / "000_G_128.png").symlink_to(outside)
    with pytest.raises(InputError, match=r"levels\.yaml: frames\[0\]\.file = '000_G_128\.png' is a symlink that"):
        read_levels(folder)


def test_a_file_name_with_a_line_break_is_named_on_one_line(dump):
    # (found by the fuzzer: YAML folds "f\n\nrames/..." into a name holding a newline)
    edit(dump / "dump.yaml", r"file: frames/000000.png", r'file: "frames/0\\n0.png"')  # (YAML's escape \n)
    with pytest.raises(InputError) as err:
        read_dump(dump)
    assert "\n" not in str(err.value) and "frames/0\\n0.png" in str(err.value)
