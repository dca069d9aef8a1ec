"""A projector whose window belongs to one thread, usable from any thread.

pyglet (like OpenGL and Xlib without XInitThreads) wants every window of a process handled by one
thread. The live session with its operator view has two windows, the projector's and the view's,
and the view needs the main thread's event loop, while the capture loop runs on its own threads.
So the main thread owns both windows, and the capture loop's calls to the projector are handed
to it: a call from another thread is queued and waits until the owner runs it in `serve()`
(the view's loop calls `serve` between redraws). A call from the owner itself runs at once.

A call that nobody serves within `timeout_s` raises DeviceError rather than hanging the session.
After `shutdown()` (the owner is leaving), further calls from other threads raise DeviceError;
`close` and `show(None)` from them are then ignored (the owner closes the window itself).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from core.errors import DeviceError
from drivers.base import Projector


class OwnerThreadProjector:
    """Wraps a thread-bound projector; `serve()` must be called by the thread that created it."""

    thread_bound = False  # CaptureLoop may call it from its projector thread

    def __init__(self, projector: Projector, timeout_s: float = 5.0) -> None:
        self.projector = projector
        self.name = projector.name
        self.size = projector.size
        self.timeout_s = timeout_s
        self._owner = threading.get_ident()
        self._cv = threading.Condition()
        self._calls: deque[_Call] = deque()
        self._closed = False
        self.served = 0  # calls run for other threads
        self.last_request_s: float | None = None  # time.monotonic() when the last call was queued

    # -- owner side ----------------------------------------------------------------------------
    def serve(self, timeout_s: float = 0.0) -> int:
        """Run the queued calls (waiting up to timeout_s for the first one); returns how many ran."""
        if threading.get_ident() != self._owner:
            raise RuntimeError("OwnerThreadProjector.serve() belongs to the thread that made it")
        with self._cv:
            if not self._calls and timeout_s > 0:
                self._cv.wait(timeout_s)
            calls = list(self._calls)
            self._calls.clear()
        for call in calls:
            call.run()
        self.served += len(calls)
        return len(calls)

    def shutdown(self) -> None:
        """The owner stops serving: queued and later calls from other threads fail (or are ignored)."""
        with self._cv:
            self._closed = True
            calls = list(self._calls)
            self._calls.clear()
        for call in calls:
            call.fail(DeviceError(f"projector {self.name}: the window was closed"))

    # -- any thread ----------------------------------------------------------------------------
    def _call(self, fn: Callable[[], Any], *, ignore_closed: bool = False) -> Any:
        if threading.get_ident() == self._owner:
            return fn()
        call = _Call(fn)
        with self._cv:
            if self._closed:
                if ignore_closed:
                    return None
                raise DeviceError(f"projector {self.name}: the window was closed")
            self._calls.append(call)
            self.last_request_s = time.monotonic()
            self._cv.notify()
        return call.wait(self.timeout_s, self.name)

    def load(self, images: Sequence[np.ndarray]) -> None:
        self._call(lambda: self.projector.load(images))

    def show(self, index: int | None) -> int | None:
        return self._call(lambda: self.projector.show(index), ignore_closed=index is None)

    def close(self) -> None:
        self._call(self.projector.close, ignore_closed=True)

    def poll(self) -> bool:
        return self._call(self.projector.poll)

    def request_stop(self) -> None:
        self.projector.request_stop()  # thread-safe by contract

    @property
    def stop_requested(self) -> bool:
        return bool(self.projector.stop_requested)


class _Call:
    def __init__(self, fn: Callable[[], Any]) -> None:
        self.fn = fn
        self.done = threading.Event()
        self.result: Any = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.result = self.fn()
        except BaseException as exc:  # handed to the calling thread
            self.error = exc
        self.done.set()

    def fail(self, exc: BaseException) -> None:
        self.error = exc
        self.done.set()

    def wait(self, timeout_s: float, name: str) -> Any:
        if not self.done.wait(timeout_s):
            raise DeviceError(f"projector {name}: its window's thread did not answer within {timeout_s:.0f} s")
        if self.error is not None:
            raise self.error
        return self.result


def thread_bound(projector: Projector) -> bool:
    """A projector whose window must be used by the thread that opened it (drivers.base.Projector)."""
    return bool(projector.thread_bound)


class HandOver:
    """`wrap_projector` for Session.make_loop: a thread-bound projector is wrapped, owned by this thread.

    The owning thread then calls `wait(s)` instead of sleeping (it serves the projector's calls
    meanwhile) and `finish()` once the capture loop has ended.
    """

    def __init__(self) -> None:
        self.proxy: OwnerThreadProjector | None = None

    def __call__(self, projector: Any) -> Any:
        if thread_bound(projector):
            self.proxy = OwnerThreadProjector(projector)
            return self.proxy
        return projector

    def wait(self, timeout_s: float) -> int:
        """Serve projector calls for up to timeout_s (returns at the first one); sleep if there is no window."""
        if self.proxy is None:
            time.sleep(timeout_s)
            return 0
        return self.proxy.serve(timeout_s)

    def finish(self) -> None:
        """The capture loop has ended: stop serving, close the window if the loop could not."""
        if self.proxy is not None:
            self.proxy.shutdown()
            self.proxy.projector.close()
            self.proxy = None
