"""Replay camera: a dump's frames and tags come back exactly, paced or not, with a clear end."""

from __future__ import annotations

import itertools
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from core.errors import DeviceError, InputError
from drivers.base import CAMERAS, Camera, CameraTimeoutError
from drivers.camera.errors import CameraStoppedError, EndOfDumpError
from drivers.camera.replay import ReplayCamera
from drivers.camera.spec import open_camera


def test_plays_every_frame_with_its_tags_then_ends(make_dump, truth):
    cam = ReplayCamera(make_dump())
    assert CAMERAS["replay"] is ReplayCamera and isinstance(cam, Camera) and len(cam) == 6
    cam.start()
    frames = [cam.grab(timeout_s=0.1) for _ in range(6)]
    assert [f.frame_id for f in frames] == truth.ids
    assert [f.pattern for f in frames] == [0, 1, 0, 1, 0, 1]
    assert [f.timestamp_ns for f in frames] == [1_000_000 + i * truth.step for i in range(6)]
    for i, f in enumerate(frames):
        np.testing.assert_array_equal(f.image, truth.image(i))
    with pytest.raises(EndOfDumpError, match=r"replay of .*dump: end of the dump \(6 frames played\)"):
        cam.grab()
    assert issubclass(EndOfDumpError, CameraStoppedError) and issubclass(EndOfDumpError, DeviceError)
    cam.close()


def test_preloaded_frames_are_the_files_and_the_dump_is_not_read_again(make_dump, truth):
    dump = make_dump()
    cam = ReplayCamera(dump, preload="true", loop=True)
    for png in Path(dump).glob("frames/*.png"):
        png.unlink()  # (played from memory: the files are no longer needed)
    cam.start()
    frames = [cam.grab(timeout_s=0.1) for _ in range(12)]
    assert [f.frame_id for f in frames[:6]] == truth.ids
    for i, f in enumerate(frames):
        np.testing.assert_array_equal(f.image, truth.image(i % 6))
    cam.close()


def test_iteration_stops_at_the_end(make_dump, truth):
    with ReplayCamera(make_dump(), start_frame=2) as cam:
        assert [f.frame_id for f in cam] == truth.ids[2:]


def test_sixteen_bit_frames_stay_sixteen_bit(make_dump, truth):
    with ReplayCamera(make_dump(bits=16)) as cam:
        cam.start()
        f = cam.grab()
    assert f.image.dtype == np.uint16
    np.testing.assert_array_equal(f.image, truth.image(0, 16))


def test_loop_keeps_ids_and_timestamps_increasing(make_dump, truth):
    with ReplayCamera(make_dump(), loop=True) as cam:
        cam.start()
        frames = [cam.grab() for _ in range(14)]
    ids = [f.frame_id for f in frames]
    ts = [f.timestamp_ns for f in frames]
    assert ids[:6] == truth.ids and ids[6] == truth.ids[0] + 7 and ids == sorted(set(ids))
    assert all(b > a for a, b in itertools.pairwise(ts))
    np.testing.assert_array_equal(frames[6].image, truth.image(0))
    assert [f.pattern for f in frames[6:12]] == [0, 1, 0, 1, 0, 1]


def test_realtime_pacing_and_timeout(make_dump, truth):
    with ReplayCamera(make_dump(), realtime=True, speed=1.0) as cam:
        cam.start()
        t = time.monotonic()
        cam.grab(timeout_s=1)
        with pytest.raises(CameraTimeoutError, match="next frame due in"):
            cam.grab(timeout_s=0.005)  # due 50 ms after the first
        f = cam.grab(timeout_s=1)  # the frame stays next
        cam.grab(timeout_s=1)
        elapsed = time.monotonic() - t
    assert f.frame_id == truth.ids[1]
    assert 0.095 <= elapsed < 1.0  # frames 0..2 span 100 ms of recording


def test_speed_scales_the_pacing(make_dump):
    with ReplayCamera(make_dump(), realtime=True, speed=4.0) as cam:
        cam.start()
        t = time.monotonic()
        for _ in range(6):
            cam.grab(timeout_s=1)
        elapsed = time.monotonic() - t
    assert 0.06 <= elapsed < 0.5  # 250 ms of recording at 4x = 62.5 ms


def test_stop_from_another_thread_ends_a_paced_wait(make_dump):
    cam = ReplayCamera(make_dump(), realtime=True, speed=0.01)  # frames 5 s apart
    cam.start()
    cam.grab()
    errors: list = []

    def wait() -> None:
        try:
            cam.grab(timeout_s=10)
        except CameraStoppedError as exc:
            errors.append(exc)

    th = threading.Thread(target=wait)
    th.start()
    time.sleep(0.05)
    cam.stop()
    th.join(timeout=1)
    assert not th.is_alive() and errors and "stopped while waiting" in str(errors[0])


def test_bad_use_and_bad_dumps(make_dump, tmp_path):
    cam = ReplayCamera(make_dump())
    with pytest.raises(CameraStoppedError, match="not streaming"):
        cam.grab()
    with pytest.raises(InputError, match=r"nowhere/dump.yaml: not found"):
        ReplayCamera(tmp_path / "nowhere")
    with pytest.raises(InputError, match="holds no frames"):
        ReplayCamera(make_dump("empty", n=0))
    with pytest.raises(InputError, match=r"start_frame=9 outside 0\.\.5"):
        ReplayCamera(make_dump("d2"), start_frame=9)
    with pytest.raises(InputError, match="realtime='maybe' must be true or false"):
        ReplayCamera(make_dump("d3"), realtime="maybe")


def test_opened_through_a_spec_and_a_config_mapping(make_dump):
    folder = make_dump()
    cam = open_camera(f"replay:{folder},realtime=true,speed=2")
    assert isinstance(cam, ReplayCamera) and cam.realtime and cam.speed == 2.0
    cam2 = open_camera({"driver": "replay", "dump": str(folder), "loop": True})
    assert cam2.loop and not cam2.realtime
