"""A camera that plays a frame dump (format v1) back, with each frame's tags.

Every Frame carries the dump's `pattern`, `frame_id` and `timestamp_ns` (the recorded device or
host time, not the playback time), so pairing and decoding see exactly what was recorded.

Pacing: as fast as asked (default), or `realtime` — frame i is released at
start + (t_i - t_0) / speed, and grab() with a shorter timeout raises CameraTimeoutError as a
real camera would (the frame stays next).

`preload`: every frame is read (PNG-decoded) when the camera is made and held in memory, so a grab costs what a
real camera's DMA does (~0 CPU): a benchmark of the pipeline behind the camera then measures that pipeline, not the
dump's PNG decoding (~20 ms a 640x480 frame).

End of the dump (the policy): grab() raises EndOfDumpError (a CameraStoppedError, so a capture
loop stops on it as on any camera that stops) once every frame has been played; iterating the
camera (`for frame in cam`) ends with StopIteration instead. With `loop`, playback wraps around
and frame ids and timestamps keep increasing (offset by one dump length per lap), so a looped
replay never looks like a camera whose counter went backwards.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from core.dump import Dump, read_dump
from core.errors import InputError
from drivers.base import CAMERAS, Frame, register
from drivers.camera.errors import CameraStoppedError, CameraTimeoutError, EndOfDumpError
from drivers.camera.spec import as_bool


@register(CAMERAS, "replay")
class ReplayCamera:
    def __init__(
        self,
        dump: str | os.PathLike | Dump,
        realtime: bool | str = False,
        speed: float | str = 1.0,
        loop: bool | str = False,
        start_frame: int | str = 0,
        name: str | None = None,
        preload: bool | str = False,
        frames: list[np.ndarray] | None = None,
    ) -> None:
        """frames: the dump's frames already read (as preload reads them), shared by several cameras over one dump."""
        self.dump = dump if isinstance(dump, Dump) else read_dump(dump)
        if not self.dump.frames:
            raise InputError(f"{self.dump.folder}: the dump holds no frames to replay")
        self.realtime = as_bool("realtime", realtime)
        self.loop = as_bool("loop", loop)
        try:
            self.speed = float(speed)
            self.position = int(start_frame)
        except ValueError:
            raise InputError(f"replay camera: speed={speed!r} / start_frame={start_frame!r} must be numbers") from None
        if self.speed <= 0:
            raise InputError(f"replay camera: speed={speed!r} must be > 0")
        if not 0 <= self.position < len(self.dump.frames):
            raise InputError(f"replay camera: start_frame={start_frame} outside 0..{len(self.dump.frames) - 1}")
        self.name = name or f"replay:{self.dump.folder}"
        self.device = f"replay of {self.dump.folder}"
        self.lap = 0
        self._streaming = False
        self._closed = False
        self._stop_event = threading.Event()
        self._t0_host = 0
        self._t0_dump = 0
        records = self.dump.frames
        self._id_period = max(r.frame_id for r in records) - min(r.frame_id for r in records) + 1
        span = records[-1].timestamp_ns - records[0].timestamp_ns
        step = span // max(1, len(records) - 1) if len(records) > 1 else 16_666_667
        self._ts_period = span + max(step, 1)
        if frames is None and as_bool("preload", preload):
            frames = preload_frames(self.dump)
        if frames is not None and len(frames) != len(records):
            raise ValueError(f"replay camera: {len(frames)} frames given for a dump of {len(records)}")
        self._frames = frames

    def __len__(self) -> int:
        return len(self.dump.frames)

    def start(self) -> None:
        if self._closed:
            raise CameraStoppedError(f"{self.device}: closed")
        self._stop_event.clear()
        self._streaming = True
        self._t0_host = time.monotonic_ns()
        self._t0_dump = self._timestamp(self.position)

    def stop(self) -> None:
        self._stop_event.set()
        self._streaming = False

    def close(self) -> None:
        self.stop()
        self._closed = True

    def _timestamp(self, i: int) -> int:
        return self.dump.frames[i].timestamp_ns + self.lap * self._ts_period

    def grab(self, timeout_s: float = 1.0) -> Frame:
        if not self._streaming:
            raise CameraStoppedError(f"{self.device}: not streaming (call start() first)")
        if self.position >= len(self.dump.frames):
            if not self.loop:
                raise EndOfDumpError(f"{self.device}: end of the dump ({len(self.dump.frames)} frames played)")
            self.position, self.lap = 0, self.lap + 1
        ts = self._timestamp(self.position)
        if self.realtime:
            due = self._t0_host + (ts - self._t0_dump) / self.speed
            wait = (due - time.monotonic_ns()) / 1e9
            if wait > timeout_s:
                if self._stop_event.wait(timeout_s):
                    raise CameraStoppedError(f"{self.device}: stopped while waiting for a frame")
                raise CameraTimeoutError(f"{self.device}: next frame due in {wait:.3f} s, after the timeout")
            if wait > 0 and self._stop_event.wait(wait):
                raise CameraStoppedError(f"{self.device}: stopped while waiting for a frame")
        rec = self.dump.frames[self.position]
        image = self.dump.load_frame(self.position) if self._frames is None else self._frames[self.position]
        self.position += 1
        return Frame(
            image=image,
            frame_id=rec.frame_id + self.lap * self._id_period,
            timestamp_ns=ts,
            pattern=rec.pattern,
            mosaic=self.dump.mosaic,
        )

    def __iter__(self) -> Iterator[Frame]:
        if not self._streaming:
            self.start()
        while True:
            try:
                yield self.grab(timeout_s=float("inf"))
            except EndOfDumpError:
                return

    def __enter__(self) -> ReplayCamera:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def preload_frames(dump: Dump) -> list[np.ndarray]:
    """Every frame of the dump, read into memory (an unreadable one: the InputError naming its file)."""
    return [dump.load_frame(i) for i in range(len(dump.frames))]
