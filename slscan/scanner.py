"""`slscan.Scanner`: a live session (the virtual rig by default) as a stream of scans.

    with slscan.Scanner() as scanner:          # config/sim.yaml: the virtual rig
        for scan in scanner.scans(10):
            print(scan.frame_ids, scan.valid.sum())

The devices open, and the decoder compiles (about a minute on a first run), in `start()` (or `with`). Capture and
decoding run on their own threads; scans wait in a small buffer until taken, and when the taker is slower than the
scanner the oldest waiting scan is dropped and counted (`dropped_scans`), never the capture. Use one Scanner from
one thread: a real projector window belongs to the thread that opened it, and that thread serves it while it waits
for scans (app/owner_thread.py).
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from app.config import Config
from app.config_keys import check_config_keys
from app.decode.pipeline import average_frames_of
from app.live_pipeline import DECODE_WORKERS, LivePipeline, LiveResult
from app.owner_thread import HandOver
from app.session import build_session
from core.calibration import Calibration
from core.errors import DeviceError, InputError
from core.patterns import PatternSet
from slscan.scan import Scan


class Scanner:
    """A live scanning session from a config: a file, a mapping with a config file's content, or None (the virtual
    rig, config/sim.yaml). scheme overrides the config's scheme.name; workers: decode threads; timeout_s: how long
    the camera may stay silent; buffer: scans kept for a slow taker before the oldest is dropped."""

    def __init__(
        self,
        config: str | os.PathLike | Mapping[str, Any] | None = None,
        *,
        scheme: str | None = None,
        workers: int = DECODE_WORKERS,
        timeout_s: float = 2.0,
        buffer: int = 4,
    ) -> None:
        if isinstance(config, Mapping):
            where = Path("<config mapping>")  # (relative paths in it: from the working directory)
            check_config_keys(where, dict(config))
            config = Config(where, dict(config))
        self._session = build_session(config, scheme=scheme)
        self.workers = max(1, int(workers))
        self.timeout_s = float(timeout_s)
        self._results: deque[LiveResult] = deque()
        self._buffer = max(1, int(buffer))
        self._cv = threading.Condition()
        self._last_index = -1
        self._pipe: LivePipeline | None = None
        self._hand_over: HandOver | None = None
        self._processor: Any = None
        self.dropped_scans = 0  # decoded but replaced by newer ones before they were taken

    # -- what it scans with ----------------------------------------------------------------------
    @property
    def calibration(self) -> Calibration:
        return self._session.calibration

    @property
    def patterns(self) -> PatternSet:
        return self._session.patterns

    @property
    def depth_range_mm(self) -> tuple[float, float] | None:
        return self._session.depth_range_mm

    @property
    def virtual_rig(self) -> Any:
        """The virtual rig (drivers/sim) when the scanner runs on it, else None: `.ground_truth.depth` is the true
        depth of the last frame it rendered."""
        sim = self._session.sim
        return None if sim is None else sim.rig

    # -- life cycle ------------------------------------------------------------------------------
    def start(self) -> Scanner:
        """Compile or load the decoder, open the devices (on this thread) and start capturing."""
        if self._pipe is not None:
            return self
        self._processor = self._session.processor()
        hand_over = HandOver()
        loop = self._session.make_loop(wrap_projector=hand_over, timeout_s=self.timeout_s)
        self._hand_over = hand_over
        self._pipe = LivePipeline(lambda: loop, self._processor, workers=self.workers, on_result=self._on_result)
        self._pipe.start()
        return self

    def close(self) -> None:
        """Stop capturing and close the devices (waits for the threads); a second call does nothing."""
        pipe, hand_over = self._pipe, self._hand_over
        if pipe is None or hand_over is None:
            return
        pipe.stop()
        try:
            while pipe.running:  # the capture loop closes a projector window through this thread
                hand_over.wait(0.01)
            pipe.join()
        finally:
            hand_over.finish()
            self._hand_over = None

    def __enter__(self) -> Scanner:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- scans -----------------------------------------------------------------------------------
    def scans(self, n: int | None = None, timeout_s: float | None = None) -> Iterator[Scan]:
        """Yield live scans in capture order, n of them or (None) until the session ends or close(). A device that
        stops, or no scan for timeout_s (default: 30 s plus the camera timeout), raises DeviceError."""
        if self._pipe is None:
            raise InputError("Scanner: start it first (scanner.start(), or `with Scanner() as scanner:`)")
        if n is not None and n < 0:
            raise InputError(f"Scanner.scans: n = {n} must be >= 0")
        wait_s = 30.0 + self.timeout_s if timeout_s is None else float(timeout_s)
        taken = 0
        while n is None or taken < n:
            result = self._next(wait_s)
            if result is None:
                return
            taken += 1
            yield self._scan(result)

    def run(self, callback: Callable[[Scan], object], n: int | None = None, timeout_s: float | None = None) -> int:
        """The callback form: call callback(scan) on this thread for every scan (as scans(n, timeout_s) yields
        them) until it returns False or n scans; returns how many it was given."""
        count = 0
        for scan in self.scans(n, timeout_s):
            count += 1
            if callback(scan) is False:
                break
        return count

    def figures(self) -> dict:
        """The session's figures: frames, depth maps, rates, latency, dropped and refused frames (LivePipeline)."""
        if self._pipe is None:
            return {}
        return {**self._pipe.figures(), "dropped_scans": self.dropped_scans}

    def _on_result(self, result: LiveResult) -> None:
        """On a decode thread: keep the newest scans, in capture order (a slower worker's older set is dropped)."""
        with self._cv:
            if result.index <= self._last_index:
                self.dropped_scans += 1
                return
            self._last_index = result.index
            if len(self._results) == self._buffer:
                self._results.popleft()
                self.dropped_scans += 1
            self._results.append(result)
            self._cv.notify_all()

    def _next(self, wait_s: float) -> LiveResult | None:
        pipe, hand_over = self._pipe, self._hand_over
        assert pipe is not None and hand_over is not None
        deadline = time.monotonic() + wait_s
        while True:
            with self._cv:
                if self._results:
                    return self._results.popleft()
                if not pipe.running:
                    if pipe.error:
                        raise DeviceError(pipe.error)
                    return None
                if hand_over.proxy is None:  # nothing to serve: sleep until a scan arrives
                    self._cv.wait(0.05)
            if hand_over.proxy is not None:
                hand_over.wait(0.005)  # serve the projector window's calls meanwhile
            if time.monotonic() > deadline:
                raise DeviceError(f"no scan within {wait_s:.0f} s (is the scene lit and inside the depth range?)")

    def _scan(self, result: LiveResult) -> Scan:
        frames = [f.image for f in result.frameset.frames]
        image = frames[0] if len(frames) != 2 else average_frames_of(frames[0], frames[1])  # stripes cancel
        if result.texture is not None:  # a white-light texture frame came before (capture.texture_every): its colour
            image = result.colour_image
        return Scan(
            result.depth,
            result.stripes.column,
            image,
            self._processor.triangulator.ray,
            frame_ids=result.frameset.frame_ids,
            timestamp_ns=result.frameset.newest.timestamp_ns,
        )
