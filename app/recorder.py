"""The recorder: tagged frames into a frame dump on a writer thread, never dropping one silently.

The capture thread hands frames over with `put`, which never blocks (a blocked capture thread
would lose camera frames instead). The queue holds `queue_frames` frames (2 s at 60 Hz by
default); if the writer falls that far behind, or the disk fills up, recording stops, the
frames not written are counted, and `message` says what happened. Everything written before
stays a readable dump (see core/dump.py: each frame is complete before its index entry exists).
"""

from __future__ import annotations

import os
import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from core.dump import DumpWriteError, DumpWriter
from drivers.base import Frame

_STOP = object()


def lower_thread_priority(niceness: int) -> None:
    """Make the calling thread yield the CPU to the others (Linux: threads have their own nice value)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), niceness)
    except (AttributeError, OSError):
        pass  # not Linux, or not allowed: the default priority still works, with less margin


@dataclass
class RecorderStats:
    queued: int = 0  # frames handed to the recorder
    written: int = 0  # frames in the dump
    not_written: int = 0  # frames handed over but not written (writer behind, disk full, stop)
    skipped_time: int = 0  # frames refused because their timestamp went back (dump rule)
    write_ms: list[float] = field(default_factory=list, repr=False)  # per-frame write time (newest 1000)

    @property
    def lost(self) -> int:
        return self.not_written + self.skipped_time


class Recorder:
    """Write frames to `writer` (a new DumpWriter) on a background thread."""

    def __init__(self, writer: DumpWriter, queue_frames: int = 120) -> None:
        self.writer = writer
        self.folder: Path = writer.folder
        self.stats = RecorderStats()
        self.message: str | None = None  # why recording stopped early, for the operator
        self._q: queue.Queue = queue.Queue(maxsize=queue_frames)
        self._failed = threading.Event()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()

    @property
    def active(self) -> bool:
        return not self._closed and not self._failed.is_set()

    def put(self, frame: Frame) -> bool:
        """Queue one tagged frame; False (and counted) if recording has stopped or cannot keep up."""
        if frame.pattern is None:
            raise ValueError("the recorder only takes tagged frames")
        if self._closed:
            return False  # recording was stopped on purpose: nothing is lost
        self.stats.queued += 1
        if not self.active:
            self.stats.not_written += 1
            return False
        try:
            self._q.put_nowait(frame)
        except queue.Full:
            self.stats.not_written += 1
            self._fail(
                f"recording stopped: the writer fell {self._q.maxsize} frames behind "
                f"(try a lower PNG level or a faster disk); {self.folder} keeps the frames written"
            )
            return False
        return True

    def _fail(self, message: str) -> None:
        if not self._failed.is_set():
            self.message = message
            self._failed.set()

    def _run(self) -> None:
        lower_thread_priority(1)  # under CPU contention the capture thread goes first; the queue absorbs it
        while True:
            item = self._q.get()
            if item is _STOP:
                return
            if self._failed.is_set():
                self.stats.not_written += 1
                continue
            t0 = time.perf_counter()
            try:
                self.writer.add(item.image, item.pattern, item.frame_id, item.timestamp_ns)
            except DumpWriteError as exc:
                self.stats.not_written += 1
                reason = "disk full" if exc.disk_full else str(exc)
                self._fail(f"recording stopped ({reason}): {self.folder} keeps the {self.stats.written} frames written")
                continue
            except ValueError:
                self.stats.skipped_time += 1
                continue
            self.stats.written += 1
            w = self.stats.write_ms
            w.append((time.perf_counter() - t0) * 1e3)
            if len(w) > 1000:
                del w[:500]

    def close(self, timeout_s: float = 30.0) -> RecorderStats:
        """Write what is queued, then finalise the dump (index flushed and synced)."""
        if not self._closed:
            self._closed = True
            self._q.put(_STOP)
            self._thread.join(timeout_s)
            if self._thread.is_alive():  # a disk that hangs: say so rather than hang with it
                self._fail(f"recording stopped: the writer did not finish within {timeout_s:.0f} s")
            while True:  # anything left behind the stop marker was not written
                try:
                    item = self._q.get_nowait()
                except queue.Empty:
                    break
                if item is not _STOP:
                    self.stats.not_written += 1
            self.writer.close()
        return self.stats

    def summary(self) -> str:
        s = self.stats
        text = f"recorded {s.written} frames to {self.folder}"
        if s.lost:
            text += f"; {s.lost} frame(s) NOT recorded"
        if self.message:
            text += f" ({self.message})"
        return text
