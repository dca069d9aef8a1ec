"""Calibration files as other tools write them: cv2.FileStorage YAML, XML and JSON, gzipped or not, sizes as
sequences or matrices; and one line for each malformed file, read without ever handing it to OpenCV."""

from __future__ import annotations

import gzip
from pathlib import Path

import cv2
import numpy as np
import pytest

import core.filestorage
from core.calibration import Calibration
from core.errors import InputError

R, _ = cv2.Rodrigues(np.array([0.01, -0.25, 0.02]))
FIELDS = {
    "camera_matrix": np.array([[1800, 0, 321.5], [0, 1801, 239.0], [0, 0, 1]]),
    "camera_distortion": np.array([[-0.1, 0.05, 0.001, -0.002, 0.0]]),
    "projector_matrix": np.array([[1500, 0, 512], [0, 1500, 700], [0, 0, 1.0]]),
    "projector_distortion": np.array([[0.02, 0, 0, 0, 1e-5]]),
    "R": R,
    "T": np.array([[-200.0], [3.0], [10.0]]),
}
SUFFIXES = [".yml", ".yaml", ".xml", ".json", ".yml.gz", ".xml.gz", ".json.gz"]


def write_with_opencv(path: Path, sizes: str) -> Path:
    """A calibration as an OpenCV program writes it: sizes as a FileStorage sequence (cv::Size, `[ 640, 480 ]`),
    a 1x2 int matrix, or what Python's cv2 makes of a tuple (a 2x1 matrix)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, (w, h) in (("camera_size", (640, 480)), ("projector_size", (1024, 768))):
        if sizes == "sequence":
            fs.startWriteStruct(key, cv2.FILE_NODE_SEQ | cv2.FILE_NODE_FLOW)
            fs.write("", w)
            fs.write("", h)
            fs.endWriteStruct()
        elif sizes == "matrix":
            fs.write(key, np.array([[w, h]], np.int32))
        else:
            fs.write(key, (w, h))
    for key, value in FIELDS.items():
        fs.write(key, value)
    fs.write("stereo_rms", 0.25)
    fs.write("camera_gamma", 2.2)
    fs.write("note", "a string field other tools add")
    fs.release()
    return path


def assert_is_the_fixture(cal: Calibration) -> None:
    assert cal.camera_size == (640, 480) and cal.projector_size == (1024, 768)
    for key, value in FIELDS.items():
        assert np.allclose(getattr(cal, key).ravel(), value.ravel()), key
    assert cal.rms == {"stereo_rms": 0.25} and cal.extra == {"camera_gamma": 2.2}


@pytest.fixture(autouse=True)
def opencv_never_reads(monkeypatch):
    """Reading a calibration never opens it with cv2.FileStorage (which can abort the process on a bad file)."""
    real = cv2.FileStorage

    def guarded(*args, **kw):
        if len(args) >= 2 and args[1] == cv2.FILE_STORAGE_READ:
            raise AssertionError("cv2.FileStorage opened a file for reading")
        return real(*args, **kw)

    monkeypatch.setattr(cv2, "FileStorage", guarded)
    return real


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize("sizes", ["sequence", "matrix", "tuple"])
def test_files_opencv_writes_are_read(tmp_path, suffix, sizes):
    path = write_with_opencv(tmp_path / f"cal{suffix}", sizes)
    if suffix.endswith(".gz"):
        assert path.read_bytes()[:2] == b"\x1f\x8b"  # OpenCV really compressed it
    assert_is_the_fixture(Calibration.load(path))


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_written_files_round_trip_say_what_r_and_t_mean_and_opencv_reads_them(tmp_path, suffix, opencv_never_reads):
    cal = Calibration.load(write_with_opencv(tmp_path / "src.yml", "matrix"))
    cal.save(tmp_path / f"out{suffix}")
    assert_is_the_fixture(Calibration.load(tmp_path / f"out{suffix}"))
    raw = (tmp_path / f"out{suffix}").read_bytes()
    text = (gzip.decompress(raw) if suffix.endswith(".gz") else raw).decode()
    assert "X_projector = R * X_camera + T" in text and "T in mm" in text and "pixels, millimetres" in text
    fs = opencv_never_reads(str(tmp_path / f"out{suffix}"), cv2.FILE_STORAGE_READ)  # our own file: OpenCV reads it
    assert np.allclose(fs.getNode("T").mat().ravel(), [-200, 3, 10])
    assert [int(v) for v in fs.getNode("camera_size").mat().ravel()] == [640, 480]
    fs.release()


def _xml(body: str) -> str:
    return f'<?xml version="1.0"?>\n<opencv_storage>\n{body}\n</opencv_storage>\n'


MALFORMED = {
    "truncated xml": (".xml", _xml("<R type_id='opencv-matrix'><rows>3</rows>")[:60], "not an OpenCV FileStorage XML"),
    "xml entities": (
        ".xml",
        '<?xml version="1.0"?><!DOCTYPE b [<!ENTITY a "aaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]><opencv_storage/>',
        "a DOCTYPE or entities",
    ),
    "xml other root": (".xml", '<?xml version="1.0"?><svg/>', "the root is <svg>, not <opencv_storage>"),
    "xml matrix count": (
        ".xml",
        _xml("<R type_id='opencv-matrix'><rows>3</rows><cols>3</cols><dt>d</dt><data>1 2 3</data></R>"),
        "an opencv-matrix of 3x3 needs 9 data values",
    ),
    "broken json": (".json", '{"camera_size": [640, 480', "not an OpenCV FileStorage JSON file"),
    "json list": (".json", "[1, 2]", "expected an object at the top level"),
    "json matrix not numbers": (
        ".json",
        '{"R": {"type_id": "opencv-matrix", "rows": 1, "cols": 1, "dt": "d", "data": ["x"]}}',
        "a value that is not a number",
    ),
    "size of three": (".yml", "%YAML:1.0\n---\ncamera_size: [ 640, 480, 3 ]\n", "'camera_size' has 3 values"),
    "size of words": (".yml", "%YAML:1.0\n---\ncamera_size: [ wide, tall ]\n", "'camera_size' is not a matrix"),
    "size fractional": (".json", '{"camera_size": [640.5, 480]}', "'camera_size' must be two positive integers"),
    "binary": (".yml", "\x00\x01\x02binary", "not a text"),
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_malformed_files_are_one_line_naming_the_file(tmp_path, name):
    suffix, content, words = MALFORMED[name]
    path = tmp_path / f"bad{suffix}"
    path.write_text(content)
    with pytest.raises(InputError) as err:
        Calibration.load(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and words in msg and "\n" not in msg, msg


def test_damaged_and_oversized_gzip_files(tmp_path, monkeypatch):
    good = write_with_opencv(tmp_path / "cal.yml.gz", "matrix").read_bytes()
    (tmp_path / "cut.yml.gz").write_bytes(good[: len(good) // 2])
    with pytest.raises(InputError, match=r"cut\.yml\.gz: a damaged gzip file"):
        Calibration.load(tmp_path / "cut.yml.gz")
    assert len(gzip.decompress(good)) > len(good) + 1
    limit = len(good) + 1  # the compressed file fits, what it expands to does not: a gzip bomb stops at the limit
    monkeypatch.setattr(core.filestorage, "MAX_BYTES", limit)
    with pytest.raises(InputError, match=rf"cal\.yml\.gz: larger than {limit:,} bytes: not a calibration file"):
        Calibration.load(tmp_path / "cal.yml.gz")


def test_the_cli_says_one_line_for_a_malformed_calibration(tmp_path, run_cli):
    bad = tmp_path / "cal.xml"
    bad.write_text(_xml("<camera_size>640</camera"))
    res = run_cli("decode", tmp_path, "--calibration", bad, "--out", tmp_path / "o")
    assert res.returncode == 2
    # the dump is checked first; point it at a real dump only to reach the calibration
    res = run_cli("sim", "render", "--scene", "plane", "--scheme", "two-shot", "--camera-size", "64x48",
                  "--out", tmp_path / "d")  # fmt: skip
    assert res.returncode == 0, res.stderr
    res = run_cli("decode", tmp_path / "d", "--calibration", bad, "--out", tmp_path / "o")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "Traceback" not in res.stderr
    assert f"{bad}: not an OpenCV FileStorage XML file" in res.stderr
