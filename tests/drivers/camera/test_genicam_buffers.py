"""GenICam buffer handling on a scripted acquirer: what viky never does (incomplete buffers, device
timestamps, 12-bit pixels), and proof that every fetched buffer goes back to the producer.

Only the harvesters boundary is faked (enumeration, ImageAcquirer, raw GenTL buffers); the driver's
own fetch, drain, conversion and queue-back code runs unchanged.
"""

from __future__ import annotations

import collections
import time

import numpy as np
import pytest

from drivers.camera import genicam as genicam_mod
from drivers.camera.errors import CameraStoppedError, UnsupportedFeatureError
from drivers.camera.genicam import GenICamCamera
from drivers.camera.gentl import HUB


class NotAvailableError(Exception):
    pass


class Stream:
    def __init__(self):
        self.queued: list[int] = []  # frame ids handed back, in order
        self.waiting: collections.deque = collections.deque()

    def queue_buffer(self, raw):
        self.queued.append(raw.frame_id)

    @property
    def num_awaiting_delivery(self):
        return len(self.waiting)


class Raw:
    def __init__(self, stream, frame_id, pixels, complete=True, ts=None, fmt_bytes=1):
        self.parent, self.frame_id, self._complete, self._ts = stream, frame_id, complete, ts
        self.height, self.width = pixels.shape
        self.raw_buffer = pixels.astype("<u2" if fmt_bytes == 2 else np.uint8).tobytes() + b"\0" * 16
        self.image_offset, self.padding_x = 0, 0

    def is_complete(self):
        return self._complete

    @property
    def timestamp_ns(self):
        if self._ts is None:
            raise NotAvailableError("timestamps not supported")
        return self._ts


class Node:
    def __init__(self, value, symbolics=None):
        self.value, self.symbolics = value, symbolics


class NodeMap:
    def __init__(self, fmt):
        self._n = {"PixelFormat": Node(fmt, [fmt]), "Width": Node(8), "Height": Node(4)}

    def has_node(self, name):
        return name in self._n

    def __getattr__(self, name):
        try:
            return self.__dict__["_n"][name]
        except KeyError:
            raise AttributeError(name) from None


class Acquirer:
    def __init__(self, fmt):
        self.stream = Stream()
        self.remote_device = type("R", (), {"node_map": NodeMap(fmt)})()
        self.data_streams = [type("D", (), {"module": self.stream})()]
        self.num_buffers, self.min_num_buffers = 0, 1
        self.started = self.destroyed = False

    def add_callback(self, event, cb):
        self.callback = cb

    def start(self):
        self.started = True

    def stop(self):
        self.started = False

    def destroy(self):
        self.destroyed = True

    def try_fetch(self, *, timeout, is_raw):
        assert is_raw
        if self.stream.waiting:
            return self.stream.waiting.popleft()
        time.sleep(min(timeout, 0.01))
        return None


class Info:
    model, serial_number, id_ = "Fake", "42", "FAKE_DEV"


@pytest.fixture
def fake(monkeypatch):
    made: list[Acquirer] = []

    def create(info):
        made.append(Acquirer(make_format[0]))
        return made[-1]

    make_format = ["Mono8"]
    monkeypatch.setattr(genicam_mod, "producer_paths", lambda *a: ["/fake.cti"])
    monkeypatch.setattr(HUB, "device_infos", lambda files: [Info()])
    monkeypatch.setattr(HUB, "create", create)

    def open_camera(fmt="Mono8", **kw):
        make_format[0] = fmt
        cam = GenICamCamera(**kw)
        return cam, made[-1]

    return open_camera


def mono(value, shape=(4, 8)):
    return np.full(shape, value, np.uint16)


def test_incomplete_buffers_are_dropped_queued_back_and_counted(fake):
    cam, ia = fake(policy="oldest")
    s = ia.stream
    s.waiting.extend([Raw(s, 1, mono(10)), Raw(s, 2, mono(20), complete=False), Raw(s, 3, mono(30))])
    cam.start()
    a, b = cam.grab(timeout_s=1), cam.grab(timeout_s=1)
    assert (a.frame_id, b.frame_id) == (1, 3) and int(b.image[0, 0, 0]) == 30
    assert s.queued == [1, 2, 3]  # every buffer back, the incomplete one included
    assert cam.stats.incomplete == 1 and cam.stats.lost == 1  # id 2 never became a frame
    ia.callback.emit()  # harvesters' own INCOMPLETE_BUFFER event is counted too
    assert cam.stats.incomplete == 2
    cam.close()
    assert ia.destroyed


def test_newest_policy_drains_and_queues_every_skipped_buffer(fake):
    cam, ia = fake()
    s = ia.stream
    s.waiting.extend(Raw(s, i, mono(i)) for i in range(1, 6))
    cam.start()
    f = cam.grab(timeout_s=1)
    assert f.frame_id == 5 and int(f.image[0, 0, 0]) == 5
    assert sorted(s.queued) == [1, 2, 3, 4, 5] and cam.stats.skipped == 4 and cam.stats.lost == 0
    cam.close()


def test_device_timestamps_used_when_the_device_has_them(fake):
    cam, ia = fake(policy="oldest")
    s = ia.stream
    s.waiting.extend([Raw(s, 1, mono(1), ts=5_000_000), Raw(s, 2, mono(2), ts=21_666_667)])
    cam.start()
    assert [cam.grab(timeout_s=1).timestamp_ns for _ in range(2)] == [5_000_000, 21_666_667]
    cam.close()


def test_twelve_bit_pixels_become_sixteen_bit_rgb(fake):
    cam, ia = fake("Mono12", policy="oldest")
    s = ia.stream
    px = np.arange(32, dtype=np.uint16).reshape(4, 8) * 100  # up to 3100 < 4096
    s.waiting.append(Raw(s, 1, px, fmt_bytes=2))
    cam.start()
    f = cam.grab(timeout_s=1)
    assert f.image.dtype == np.uint16 and f.image.shape == (4, 8, 3)
    np.testing.assert_array_equal(f.image[..., 1], px << 4)
    cam.close()


def test_a_conversion_failure_still_queues_the_buffer(fake):
    cam, ia = fake(policy="oldest")
    s = ia.stream
    bad = Raw(s, 1, mono(1))
    bad.raw_buffer = b"\0" * 5  # shorter than 8x4 Mono8
    s.waiting.append(bad)
    cam.start()
    with pytest.raises(UnsupportedFeatureError, match=r"Fake serial=42 .*buffer holds 5 bytes, needs 32"):
        cam.grab(timeout_s=1)
    assert s.queued == [1]
    cam.close()


def test_stop_then_grab_and_close_twice(fake):
    cam, _ = fake()
    cam.start()
    cam.stop()
    with pytest.raises(CameraStoppedError, match="not streaming"):
        cam.grab(timeout_s=0.1)
    cam.close()
    cam.close()


def test_newest_drain_is_bounded_against_a_runaway_producer(fake):
    """A producer that always has another buffer waiting cannot keep grab() draining forever."""
    cam, ia = fake(buffers=4)
    s = ia.stream
    counter = iter(range(1, 10**6))

    def endless(*, timeout, is_raw):
        return Raw(s, next(counter), mono(1))

    ia.try_fetch = endless
    type(s).num_awaiting_delivery = property(lambda self: 1)
    try:
        cam.start()
        t = time.monotonic()
        f = cam.grab(timeout_s=1)
        assert time.monotonic() - t < 0.5
        assert f.frame_id == 9 and cam.stats.skipped == 8  # 2 x 4 buffers at most
        assert s.queued == list(range(1, 10))  # the 8 skipped, then the returned frame's own buffer
        cam.close()
    finally:
        type(s).num_awaiting_delivery = property(lambda self: len(self.waiting))
