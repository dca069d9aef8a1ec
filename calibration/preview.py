"""The wizard's live view, produced off the UI thread: the newest camera image and its board detection.

Board detection takes ~0.13 s at 640x480 and moving the virtual rig's board (a re-precomputation
of the scene) ~0.3 s: done in the key handler, each key froze the window for about half a second
(a second on the loaded machine). A worker thread now runs the newest job only (older ones are
superseded), detects the board and publishes the result; the window polls for it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibration.board import Board, Detection, detect


@dataclass(frozen=True)
class View:
    seq: int  # increases with every published view
    job: int  # the submitted job this view answers
    image: np.ndarray
    detection: Detection | None


Job = Callable[[], "np.ndarray | tuple[np.ndarray, Detection | None] | None"]


class PreviewWorker:
    """Runs the newest submitted job (a callable returning a camera image), then detects the board.

    A job may return (image, detection) when it has the detection already (a prefetched view).
    """

    def __init__(self, board: Board, name: str = "calibration-preview") -> None:
        self.board = board
        self._cond = threading.Condition()
        self._job: Job | None = None
        self._submitted = 0  # jobs submitted so far
        self._done = 0  # the last job finished (published or failed)
        self._view: View | None = None
        self._seq = 0
        self._stop = False
        self.error = ""  # the last job's failure, shown by the window
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: Job) -> int:
        """Queue `job`, replacing any job not started yet; returns its number."""
        with self._cond:
            self._submitted += 1
            self._job = job
            self._cond.notify_all()
            return self._submitted

    def latest(self) -> View | None:
        with self._cond:
            return self._view

    def wait(self, job: int | None = None, timeout_s: float = 30.0) -> View | None:
        """Block until job `job` (default: the last submitted) is done; the newest view."""
        with self._cond:
            target = self._submitted if job is None else job
            self._cond.wait_for(lambda: self._done >= target or self._stop, timeout_s)
            return self._view

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._job is not None or self._stop)
                if self._stop:
                    return
                job, self._job, number = self._job, None, self._submitted
            try:
                image = job()  # type: ignore[misc]
                if isinstance(image, tuple):
                    image, det = image
                else:
                    det = detect(self.board, image) if image is not None else None
            except Exception as exc:  # a device or pose error: shown, the worker goes on
                with self._cond:
                    self.error = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                    self._done = number
                    self._cond.notify_all()
                continue
            with self._cond:
                if image is not None:
                    self._seq += 1
                    self._view = View(self._seq, number, image, det)
                    self.error = ""
                self._done = number
                self._cond.notify_all()

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(5.0)
