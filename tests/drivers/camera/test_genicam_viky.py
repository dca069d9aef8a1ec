"""The GenICam driver against the real `viky.cti` GenTL producer of the genicam wheel, through real harvesters.

viky offers three virtual cameras, VikyTL_DEV_red/green/blue (serials 0/1/2, model "Viky"), a
white image with a small ball in its colour, RGBa8 or Mono8, 1-200 fps, no trigger/exposure/gain.
"""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from drivers.base import CAMERAS, Camera, CameraTimeoutError
from drivers.camera.errors import (
    CameraStoppedError,
    DeviceBusyError,
    NoDeviceError,
    NoProducerError,
    UnsupportedFeatureError,
)
from drivers.camera.genicam import GenICamCamera
from drivers.camera.gentl import HUB, viky_path

pytestmark = pytest.mark.skipif(not os.path.isfile(viky_path()), reason="genicam wheel without viky.cti")


def viky(**kw) -> GenICamCamera:
    kw.setdefault("use_env", False)
    return GenICamCamera(cti="viky", **kw)


@pytest.fixture(autouse=True)
def no_leftover_cameras():
    yield
    assert HUB.open_count == 0, "a test left a GenICam camera open"


def test_registered_and_implements_camera():
    assert CAMERAS["genicam"] is GenICamCamera
    with viky(serial="0") as cam:
        assert isinstance(cam, Camera)


@pytest.mark.parametrize(
    ("selection", "device_id"),
    [
        ({"serial": "2"}, "VikyTL_DEV_blue"),
        ({"serial": 1}, "VikyTL_DEV_green"),  # a number from YAML or a spec is a serial all the same
        ({"index": 0}, "VikyTL_DEV_red"),
        ({"model": "Viky", "index": 1}, "VikyTL_DEV_green"),
        ({"device_id": "VikyTL_DEV_blue"}, "VikyTL_DEV_blue"),
    ],
)
def test_open_by_serial_model_index(selection, device_id):
    with viky(**selection) as cam:
        assert device_id in cam.device


def test_ambiguous_or_missing_selection_names_the_devices():
    with pytest.raises(NoDeviceError, match=r"3 GenICam cameras match model=Viky .*add serial= or index="):
        viky(model="Viky")
    with pytest.raises(NoDeviceError, match=r"no GenICam camera matches serial=99; found: .*serial=0 \(VikyTL_DEV_red"):
        viky(serial="99")
    with pytest.raises(NoDeviceError, match="index=7 among 3"):
        viky(index=7)


def test_rgba8_frames_keep_the_colour_order():
    """Each virtual camera draws a ball in its own colour on white: red stays red (RGB, not BGR)."""
    for serial, colour in (("0", (255, 0, 0)), ("1", (0, 255, 0)), ("2", (0, 0, 255))):
        with viky(serial=serial, pixel_format="RGBa8", policy="oldest") as cam:
            cam.start()
            f = cam.grab(timeout_s=2)
        assert f.image.shape == (400, 400, 3) and f.image.dtype == np.uint8
        values, counts = np.unique(f.image.reshape(-1, 3), axis=0, return_counts=True)
        assert {tuple(v) for v in values} == {(255, 255, 255), colour}, serial
        assert counts.min() > 100  # the ball is a real blob, not a stray pixel


def test_mono8_frames_roi_and_consecutive_frame_ids():
    with viky(serial="1", pixel_format="Mono8", width=320, height=240, frame_rate=100, policy="oldest") as cam:
        assert cam.pixel_format == "Mono8"
        cam.start()
        t0 = time.monotonic_ns()
        frames = [cam.grab(timeout_s=2) for _ in range(10)]
        t1 = time.monotonic_ns()
    assert [f.frame_id for f in frames] == list(range(1, 11))  # viky counts from 1 per start
    for f in frames:
        assert f.image.shape == (240, 320, 3)
        assert (f.image[..., 0] == f.image[..., 1]).all() and (f.image[..., 1] == f.image[..., 2]).all()
    ts = [f.timestamp_ns for f in frames]  # viky has no device timestamps: host monotonic time
    assert t0 <= ts[0] and ts == sorted(ts) and ts[-1] <= t1
    assert cam.stats.frames == 10 and cam.stats.lost == 0 and cam.stats.skipped == 0


def test_frame_rate_setting_changes_the_rate():
    with viky(serial="2", pixel_format="Mono8", width=100, height=100, frame_rate=5, policy="oldest") as cam:
        cam.start()
        cam.grab(timeout_s=2)
        t = time.monotonic()
        for _ in range(3):
            cam.grab(timeout_s=2)
        slow = (time.monotonic() - t) / 3
    assert 0.12 < slow < 0.5  # 5 fps = 0.2 s a frame


def test_every_buffer_is_queued_back():
    """With 2 buffers, 60 frames only arrive if each fetched buffer went back to the producer."""
    with viky(serial="0", pixel_format="Mono8", width=100, height=100, frame_rate=200, buffers=2, policy="oldest") as c:
        c.start()
        ids = [c.grab(timeout_s=1).frame_id for _ in range(60)]
    assert ids == sorted(ids) and len(set(ids)) == 60


def test_newest_policy_skips_and_counts():
    with viky(serial="0", pixel_format="Mono8", width=100, height=100, frame_rate=200, buffers=6) as cam:
        cam.start()
        first = cam.grab(timeout_s=2)
        time.sleep(0.3)  # 60 frames produced meanwhile; at most 6 buffers hold them
        newest = cam.grab(timeout_s=2)
        s = cam.stats
    assert s.skipped >= 3
    assert newest.frame_id - first.frame_id - 1 == s.skipped + s.lost  # every missing id is accounted for


def test_timeout_raises_promptly():
    with viky(serial="1", pixel_format="Mono8", frame_rate=2, policy="oldest") as cam:
        cam.start()
        cam.grab(timeout_s=3)
        t = time.monotonic()
        with pytest.raises(CameraTimeoutError, match=r"Viky serial=1 .*no frame within the timeout"):
            cam.grab(timeout_s=0.15)
        assert time.monotonic() - t < 0.6
        assert cam.stats.timeouts == 1


def test_features_viky_lacks_are_clear_errors():
    with pytest.raises(UnsupportedFeatureError, match=r"serial=0 .*no TriggerMode feature.*cannot run hardwa"):
        viky(serial="0", trigger="Line1")
    with pytest.raises(UnsupportedFeatureError, match="has no ExposureTime feature"):
        viky(serial="0", exposure_us=5000)
    with pytest.raises(UnsupportedFeatureError, match="has no Gain feature"):
        viky(serial="0", gain_db=3)
    with pytest.raises(UnsupportedFeatureError, match="has no OffsetX feature"):
        viky(serial="0", roi=[10, 0, 200, 200])
    with pytest.raises(UnsupportedFeatureError, match=r"Width=5000 is outside its range 100..800"):
        viky(serial="0", width=5000)


def test_pixel_formats_the_camera_or_slscan_cannot_do():
    with pytest.raises(UnsupportedFeatureError, match=r"PixelFormat 'BayerRG8' is not offered .*RGBa8, Mono8"):
        viky(serial="0", pixel_format="BayerRG8")
    with pytest.raises(UnsupportedFeatureError, match=r"cannot convert pixel format 'YCbCr422_8' \(supported: RGBa8"):
        viky(serial="0", pixel_format="YCbCr422_8")


def test_bad_producer_paths(tmp_path):
    with pytest.raises(NoProducerError, match=r"nope.cti: GenTL producer \(.cti\) not found"):
        GenICamCamera(cti=str(tmp_path / "nope.cti"), use_env=False)
    fake = tmp_path / "fake.cti"
    fake.write_text("not a library")
    with pytest.raises(NoProducerError, match=r"fake.cti: not a loadable GenTL producer"):
        GenICamCamera(cti=str(fake), use_env=False)
    with pytest.raises(NoProducerError, match=r"empty: folder holds no GenTL producer"):
        (tmp_path / "empty").mkdir()
        GenICamCamera(cti=str(tmp_path / "empty"), use_env=False)
    with pytest.raises(NoProducerError, match=r"no GenTL producer .* GENICAM_GENTL64_PATH"):
        GenICamCamera(use_env=False)


def test_producer_found_through_genicam_gentl64_path(tmp_path, monkeypatch):
    (tmp_path / "viky.cti").symlink_to(viky_path())
    monkeypatch.setenv("GENICAM_GENTL64_PATH", f"/does/not/exist{os.pathsep}{tmp_path}")
    with GenICamCamera(serial="2") as cam:
        cam.start()
        assert cam.grab(timeout_s=2).frame_id == 1


def test_device_busy_then_free():
    first = viky(serial="0")
    try:
        with pytest.raises(DeviceBusyError, match=r"Viky serial=0 \(VikyTL_DEV_red\) is in use"):
            viky(serial="0")
    finally:
        first.close()
    with viky(serial="0") as again:
        again.start()
        assert again.grab(timeout_s=2).frame_id == 1


def test_close_while_grab_waits_in_another_thread_then_reopen():
    cam = viky(serial="1", pixel_format="Mono8", frame_rate=2, policy="oldest")
    cam.start()
    cam.grab(timeout_s=3)
    outcome: list = []

    def waiter() -> None:
        t = time.monotonic()
        try:
            cam.grab(timeout_s=10)
            outcome.append("frame")
        except CameraStoppedError as exc:
            outcome.append((exc, time.monotonic() - t))

    th = threading.Thread(target=waiter)
    th.start()
    time.sleep(0.2)
    t = time.monotonic()
    cam.close()
    assert time.monotonic() - t < 1.0
    th.join(timeout=2)
    assert not th.is_alive()
    assert outcome and outcome[0] != "frame" and "stopped while waiting" in str(outcome[0][0])
    with pytest.raises(CameraStoppedError, match="not streaming"):
        cam.grab(timeout_s=0.1)
    cam.open()  # reopen after close: same object, settings applied again
    try:
        cam.start()
        f = cam.grab(timeout_s=3)
        assert f.frame_id == 1 and f.image.shape == (400, 400, 3)
    finally:
        cam.close()


def test_vanished_device_raises_promptly_and_can_be_reopened():
    """The producer released under a streaming camera (as on unplug): a typed error, no hang, reopen works."""
    cam = viky(serial="2", pixel_format="Mono8")
    cam.start()
    cam.grab(timeout_s=2)
    HUB.reset()
    t = time.monotonic()
    with pytest.raises(CameraStoppedError, match=r"serial=2 .*stopped answering"):
        cam.grab(timeout_s=5)
    assert time.monotonic() - t < 1.0
    cam.close()
    cam.open()
    try:
        cam.start()
        assert cam.grab(timeout_s=2).frame_id == 1
    finally:
        cam.close()


def test_producers_are_released_when_the_last_camera_closes():
    """harvesters: a second Harvester sees 0 devices while another holds the producer."""
    from harvesters.core import Harvester

    with viky(serial="0") as cam:
        cam.start()
        cam.grab(timeout_s=2)
    with Harvester() as other:  # code elsewhere in the process that makes its own
        other.add_file(viky_path())
        other.update()
        assert len(other.device_info_list) == 3
    with viky(serial="1") as cam:  # and the driver still works afterwards
        cam.start()
        assert cam.grab(timeout_s=2).frame_id == 1


def test_stop_and_start_again_restarts_the_stream():
    with viky(serial="0", pixel_format="Mono8", frame_rate=100, policy="oldest") as cam:
        for _ in range(3):
            cam.start()
            ids = [cam.grab(timeout_s=2).frame_id for _ in range(3)]
            cam.stop()
            assert ids == [1, 2, 3]  # viky counts from 1 per start; no false "lost" across restarts
        assert cam.stats.lost == 0 and cam.stats.frames == 9
