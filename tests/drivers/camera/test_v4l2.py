"""V4L2 driver against a mocked cv2.VideoCapture (no /dev/video* on these machines).

The fake behaves like a UVC camera behind OpenCV: set() may be ignored or approximated, so the
driver must read every setting back; read() blocks for a frame period and returns BGR.
"""

from __future__ import annotations

import threading
import time
from typing import ClassVar

import cv2
import numpy as np
import pytest

from drivers.base import CAMERAS, CameraTimeoutError
from drivers.camera import v4l2
from drivers.camera.errors import CameraStoppedError, DeviceBusyError, NoDeviceError, UnsupportedFeatureError
from drivers.camera.spec import open_camera
from drivers.camera.v4l2 import V4L2Camera, fourcc_code, fourcc_text

MODES = {"YUYV": [(640, 480)], "MJPG": [(640, 480), (1280, 720)]}
RATES = (30.0, 60.0)


class FakeCapture:
    instances: ClassVar[list[FakeCapture]] = []

    def __init__(self, source, api):
        self.source, self.api = source, api
        self.opened = True
        self.props = {
            cv2.CAP_PROP_FOURCC: float(fourcc_code("YUYV")),
            cv2.CAP_PROP_FRAME_WIDTH: 640.0,
            cv2.CAP_PROP_FRAME_HEIGHT: 480.0,
            cv2.CAP_PROP_FPS: 30.0,
            cv2.CAP_PROP_EXPOSURE: 156.0,
            cv2.CAP_PROP_AUTO_EXPOSURE: 3.0,
            cv2.CAP_PROP_POS_MSEC: 0.0,
        }
        self.sets: list[tuple[int, float]] = []
        self.read_delay = 0.0
        self.fail_reads = False
        self.reads = 0
        self.concurrent = 0
        self.max_concurrent = 0
        self.released = False
        self._lock = threading.Lock()
        FakeCapture.instances.append(self)

    def isOpened(self):  # noqa: N802 (OpenCV's name)
        return self.opened

    def set(self, prop, value):
        self.sets.append((prop, value))
        fmt = fourcc_text(self.props[cv2.CAP_PROP_FOURCC])
        if prop == cv2.CAP_PROP_FOURCC:
            if fourcc_text(value) in MODES:  # anything else: silently ignored, as V4L2 does
                self.props[prop] = float(value)
            return True
        if prop in (cv2.CAP_PROP_FRAME_WIDTH, cv2.CAP_PROP_FRAME_HEIGHT):
            want = dict(self.props)
            want[prop] = float(value)
            size = (int(want[cv2.CAP_PROP_FRAME_WIDTH]), int(want[cv2.CAP_PROP_FRAME_HEIGHT]))
            if size not in MODES[fmt]:
                size = next((s for s in MODES[fmt] if s[prop == cv2.CAP_PROP_FRAME_HEIGHT] == int(value)), size)
            if size in MODES[fmt]:
                self.props[cv2.CAP_PROP_FRAME_WIDTH], self.props[cv2.CAP_PROP_FRAME_HEIGHT] = map(float, size)
            return True
        if prop == cv2.CAP_PROP_FPS:
            self.props[prop] = min(RATES, key=lambda r: abs(r - value))
            return True
        if prop in self.props:
            self.props[prop] = float(value)
            return True
        return False

    def get(self, prop):
        return self.props.get(prop, 0.0)

    def read(self):
        with self._lock:
            self.concurrent += 1
            self.max_concurrent = max(self.max_concurrent, self.concurrent)
        try:
            time.sleep(self.read_delay)
            if self.fail_reads:
                return False, None
            self.reads += 1
            w, h = int(self.props[cv2.CAP_PROP_FRAME_WIDTH]), int(self.props[cv2.CAP_PROP_FRAME_HEIGHT])
            bgr = np.empty((h, w, 3), np.uint8)
            bgr[...] = (10, 20, 30)
            bgr[0, 0] = (self.reads, 0, 0)
            self.props[cv2.CAP_PROP_POS_MSEC] = 1000.0 + 33.0 * self.reads
            return True, bgr
        finally:
            with self._lock:
                self.concurrent -= 1

    def release(self):
        self.released_while_reading = self.concurrent > 0
        self.released = True


@pytest.fixture
def devices(tmp_path, monkeypatch):
    """A /dev with video0 and video2, and cv2.VideoCapture replaced at the driver boundary."""
    for n in (0, 2):
        (tmp_path / f"video{n}").touch()
    monkeypatch.setattr(v4l2, "DEV_DIR", tmp_path)
    FakeCapture.instances = []
    monkeypatch.setattr(v4l2, "VideoCapture", FakeCapture)
    return tmp_path


def test_registered():
    assert CAMERAS["v4l2"] is V4L2Camera


def test_open_by_index_and_by_path(devices):
    with V4L2Camera(2) as cam:
        assert FakeCapture.instances[-1].source == 2 and FakeCapture.instances[-1].api == cv2.CAP_V4L2
        assert str(devices / "video2") in cam.device
    with V4L2Camera(str(devices / "video0")):
        assert FakeCapture.instances[-1].source == str(devices / "video0")
    assert all(c.released for c in FakeCapture.instances)


def test_missing_and_busy_devices(devices, monkeypatch):
    with pytest.raises(NoDeviceError, match=r"video1: no such V4L2 device"):
        V4L2Camera(1)

    class Busy(FakeCapture):
        def __init__(self, *a):
            super().__init__(*a)
            self.opened = False

    monkeypatch.setattr(v4l2, "VideoCapture", Busy)
    with pytest.raises(DeviceBusyError, match=r"video0: cannot open \(busy in another program"):
        V4L2Camera(0)
    assert FakeCapture.instances[-1].released


def test_fourcc_size_fps_exposure_are_set_and_read_back(devices):
    with V4L2Camera(0, fourcc="MJPG", width=1280, height=720, fps=60, exposure_us=5000) as cam:
        fake = FakeCapture.instances[-1]
        assert fourcc_text(fake.props[cv2.CAP_PROP_FOURCC]) == "MJPG"
        assert (fake.props[cv2.CAP_PROP_FRAME_WIDTH], fake.props[cv2.CAP_PROP_FRAME_HEIGHT]) == (1280, 720)
        assert fake.props[cv2.CAP_PROP_FPS] == 60
        assert fake.props[cv2.CAP_PROP_AUTO_EXPOSURE] == 1 and fake.props[cv2.CAP_PROP_EXPOSURE] == 50
        props = [p for p, _ in fake.sets]
        assert props.index(cv2.CAP_PROP_FOURCC) < props.index(cv2.CAP_PROP_FRAME_WIDTH)  # format first
        cam.start()
        assert cam.grab(timeout_s=1).image.shape == (720, 1280, 3)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"fourcc": "H264"}, "FOURCC H264 not accepted (camera gives YUYV)"),
        ({"width": 1280, "height": 720}, "size 1280x720 not offered in this format (camera chose 640x480)"),
        ({"fps": 120}, "120 fps not offered (the camera chose 60)"),
    ],
)
def test_settings_the_camera_ignores_are_errors(devices, options, message):
    with pytest.raises(UnsupportedFeatureError, match=r"video0: " + message.replace("(", r"\(").replace(")", r"\)")):
        V4L2Camera(0, **options)
    assert FakeCapture.instances[-1].released


def test_frames_are_rgb_with_ids_and_device_timestamps(devices):
    with V4L2Camera(0) as cam:
        cam.start()
        frames = [cam.grab(timeout_s=1) for _ in range(3)]
    assert [f.frame_id for f in frames] == [1, 2, 3]
    assert [f.timestamp_ns for f in frames] == [int((1000 + 33 * i) * 1e6) for i in (1, 2, 3)]
    img = frames[1].image
    assert img.dtype == np.uint8 and img.shape == (480, 640, 3)
    assert tuple(img[5, 5]) == (30, 20, 10)  # BGR (10, 20, 30) from OpenCV -> RGB
    assert tuple(img[0, 0]) == (0, 0, 2)  # the fake's frame counter lands in the blue channel


def test_grab_timeout_is_bounded_and_reads_never_overlap(devices):
    with V4L2Camera(0) as cam:
        fake = FakeCapture.instances[-1]
        fake.read_delay = 1.0
        cam.start()
        t = time.monotonic()
        with pytest.raises(CameraTimeoutError, match=r"video0: no frame within 0.1 s"):
            cam.grab(timeout_s=0.1)
        assert time.monotonic() - t < 0.6
        f = cam.grab(timeout_s=2)  # collects the read that was already under way
        assert f.frame_id == 1 and fake.reads == 1 and fake.max_concurrent == 1


def test_close_during_a_pending_read_releases_after_it(devices):
    cam = V4L2Camera(0)
    fake = FakeCapture.instances[-1]
    fake.read_delay = 0.3
    cam.start()
    with pytest.raises(CameraTimeoutError):
        cam.grab(timeout_s=0.05)
    cam.close()  # returns at once; OpenCV's release waits for the read on the reader thread
    deadline = time.monotonic() + 2
    while not fake.released and time.monotonic() < deadline:
        time.sleep(0.01)
    assert fake.released and not fake.released_while_reading and fake.reads == 1


def test_unplugged_camera_stops_with_a_message_and_reopens(devices):
    cam = V4L2Camera(0)
    cam.start()
    cam.grab(timeout_s=1)
    FakeCapture.instances[-1].fail_reads = True
    with pytest.raises(CameraStoppedError, match=r"video0 stopped delivering frames"):
        cam.grab(timeout_s=1)
    with pytest.raises(CameraStoppedError, match="not streaming"):
        cam.grab(timeout_s=1)
    cam.close()
    cam.open()
    cam.start()
    assert cam.grab(timeout_s=1).frame_id == 1
    cam.close()


def test_open_through_a_spec(devices):
    cam = open_camera("v4l2:0,fourcc=MJPG,width=1280,height=720,fps=30")
    try:
        assert isinstance(cam, V4L2Camera) and (cam.width, cam.height, cam.fps) == (1280, 720, 30.0)
    finally:
        cam.close()
