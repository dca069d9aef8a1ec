"""Calibration YAML: OpenCV FileStorage round trip and clear errors on bad files."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from core.calibration import Calibration
from core.errors import InputError


def make() -> Calibration:
    R, _ = cv2.Rodrigues(np.array([0.01, -0.25, 0.02]))
    return Calibration(
        camera_size=(640, 480),
        camera_matrix=[[1800, 0, 321.5], [0, 1801, 239.0], [0, 0, 1]],
        camera_distortion=[-0.1, 0.05, 0.001, -0.002, 0.0],
        projector_size=(1024, 768),
        projector_matrix=[[1500, 0, 512], [0, 1500, 700], [0, 0, 1]],
        projector_distortion=[0.02, 0, 0, 0, 0],
        R=R,
        T=[-200.0, 3.0, 10.0],
        rms={"camera_rms": 0.11, "projector_rms": 0.2, "stereo_rms": 0.25},
        color_mixing=[[1.0, 0.1, 0.02], [0.08, 1.0, 0.12], [0.01, 0.1, 1.0]],
    )


def test_round_trip_and_opencv_reads_it(tmp_path):
    c = make()
    c.save(tmp_path / "c.yaml")
    back = Calibration.load(tmp_path / "c.yaml")
    for key in ("camera_matrix", "camera_distortion", "projector_matrix", "projector_distortion", "R", "T"):
        assert np.allclose(getattr(back, key), getattr(c, key)), key
    assert back.camera_size == (640, 480) and back.projector_size == (1024, 768)
    assert back.rms == pytest.approx(c.rms)
    assert np.allclose(back.color_mixing, c.color_mixing)
    fs = cv2.FileStorage(str(tmp_path / "c.yaml"), cv2.FILE_STORAGE_READ)
    assert np.allclose(fs.getNode("T").mat().ravel(), [-200, 3, 10])
    assert fs.getNode("R").mat().shape == (3, 3)
    assert back.baseline_mm == pytest.approx(np.linalg.norm([-200, 3, 10]))
    assert np.allclose(back.R @ back.projector_center_in_camera + back.T, 0)


def test_without_color_mixing(tmp_path):
    c = make()
    c.color_mixing = None
    c.save(tmp_path / "c.yaml")
    assert Calibration.load(tmp_path / "c.yaml").color_mixing is None


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda fs, c: c.__setattr__("R", np.diag([1.0, 1.0, 2.0])), "'R' is not a rotation"),
        (lambda fs, c: c.__setattr__("T", np.zeros(3)), "'T' is zero"),
        (lambda fs, c: c.__setattr__("camera_matrix", -np.eye(3)), "camera_matrix"),
        (lambda fs, c: c.__setattr__("color_mixing", np.ones((3, 3))), "color_mixing"),
    ],
)
def test_impossible_values_are_refused(tmp_path, edit, words):
    c = make()
    edit(None, c)
    c.save(tmp_path / "c.yaml")
    with pytest.raises(InputError, match=words):
        Calibration.load(tmp_path / "c.yaml")


def test_missing_field_named(tmp_path):
    make().save(tmp_path / "c.yaml")
    text = (tmp_path / "c.yaml").read_text()
    start = text.index("projector_matrix:")
    end = text.index("projector_distortion:")
    (tmp_path / "c.yaml").write_text(text[:start] + text[end:])
    with pytest.raises(InputError, match="missing field 'projector_matrix'"):
        Calibration.load(tmp_path / "c.yaml")


@pytest.mark.parametrize("content", ["", "not: [yaml", "%YAML:1.0\n---\nfoo: 1\n", "\x00\x01binary"])
def test_garbage_files(tmp_path, content):
    (tmp_path / "c.yaml").write_text(content)
    with pytest.raises(InputError, match=r"c\.yaml"):
        Calibration.load(tmp_path / "c.yaml")


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        Calibration.load(tmp_path / "nope.yaml")
