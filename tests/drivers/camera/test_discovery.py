"""list_cameras: GenICam devices per producer (real viky.cti), V4L2 nodes, and producer problems."""

from __future__ import annotations

import pytest

from drivers.camera import v4l2
from drivers.camera.discovery import list_cameras
from drivers.camera.genicam import GenICamCamera
from drivers.camera.gentl import HUB, viky_path
from drivers.camera.spec import open_camera


def test_viky_devices_with_specs_that_open_them():
    found = list_cameras([viky_path()], use_env=False, v4l2=False)
    assert [(c["serial"], c["device_id"]) for c in found] == [
        ("0", "VikyTL_DEV_red"),
        ("1", "VikyTL_DEV_green"),
        ("2", "VikyTL_DEV_blue"),
    ]
    for c in found:
        assert c["driver"] == "genicam" and c["producer"] == viky_path() and c["model"] == "Viky"
        assert c["access"] == "available"
    cam = open_camera(found[2]["spec"])  # the listed spec opens that very camera
    try:
        assert isinstance(cam, GenICamCamera) and "VikyTL_DEV_blue" in cam.device
    finally:
        cam.close()
    assert HUB.open_count == 0


def test_producer_problems_are_entries_not_exceptions(tmp_path):
    found = list_cameras([tmp_path / "gone.cti", "viky"], use_env=False, v4l2=False)
    errors = [c for c in found if "error" in c]
    assert len(errors) == 1 and "gone.cti: GenTL producer (.cti) not found" in errors[0]["error"]
    assert sum(1 for c in found if c.get("model") == "Viky") == 3
    nothing = list_cameras([], use_env=False, v4l2=False)
    assert len(nothing) == 1 and "no GenTL producer" in nothing[0]["error"]


def test_v4l2_nodes_are_listed(tmp_path, monkeypatch):
    for n in (0, 1, 10):
        (tmp_path / f"video{n}").touch()
    monkeypatch.setattr(v4l2, "DEV_DIR", tmp_path)
    found = [c for c in list_cameras([], use_env=False) if c["driver"] == "v4l2"]
    assert [c["device"] for c in found] == [str(tmp_path / f"video{n}") for n in (0, 1, 10)]
    assert found[0]["spec"] == f"v4l2:{tmp_path / 'video0'}"


@pytest.fixture(autouse=True)
def no_leftover_cameras():
    yield
    assert HUB.open_count == 0
