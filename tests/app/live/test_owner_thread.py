"""app/owner_thread.py: a thread-bound projector's calls run on its owner thread, in order, with
their results and errors handed back; nothing hangs when the owner stops serving."""

from __future__ import annotations

import threading
import time

import pytest

from app.owner_thread import HandOver, OwnerThreadProjector, thread_bound
from core.errors import DeviceError, InputError


class WindowLike:
    """Records which thread ran each call, like a pyglet window that must stay on one thread."""

    name, size = "fake", (8, 6)
    thread_bound = True

    def __init__(self) -> None:
        self.calls: list[tuple[str, object, int]] = []
        self.closed = False
        self.stop_requested = False

    def load(self, images) -> None:
        self.calls.append(("load", len(images), threading.get_ident()))

    def show(self, index):
        if index == 99:
            raise InputError("pattern index 99 is out of range")
        self.calls.append(("show", index, threading.get_ident()))
        return 1000 + (index or 0)

    def close(self) -> None:
        self.closed = True
        self.calls.append(("close", None, threading.get_ident()))

    def request_stop(self) -> None:
        self.stop_requested = True


def test_calls_from_another_thread_run_on_the_owner_in_order():
    win = WindowLike()
    proxy = OwnerThreadProjector(win)
    owner = threading.get_ident()
    out: dict = {}

    def capture_thread() -> None:
        out["shows"] = [proxy.show(i % 2) for i in range(5)]
        with pytest.raises(InputError, match="99"):
            proxy.show(99)
        out["done"] = True

    t = threading.Thread(target=capture_thread)
    t.start()
    deadline = time.monotonic() + 10
    while t.is_alive() and time.monotonic() < deadline:
        proxy.serve(0.01)
    t.join()
    assert out == {"shows": [1000, 1001, 1000, 1001, 1000], "done": True}
    assert [(c[0], c[1]) for c in win.calls] == [("show", i % 2) for i in range(5)]
    assert {c[2] for c in win.calls} == {owner}
    assert proxy.served == 6
    proxy.load([1, 2])  # the owner's own call runs at once
    assert win.calls[-1] == ("load", 2, owner)
    assert not proxy.thread_bound and thread_bound(win) and not thread_bound(proxy)


def test_an_unserved_call_times_out_and_a_stopped_owner_refuses_or_ignores():
    win = WindowLike()
    proxy = OwnerThreadProjector(win, timeout_s=0.2)
    errors: list[BaseException] = []

    def call(fn) -> None:
        try:
            fn()
        except BaseException as exc:
            errors.append(exc)

    t = threading.Thread(target=call, args=(lambda: proxy.show(1),))
    t.start()
    t.join(5)
    assert isinstance(errors[0], DeviceError) and "did not answer within" in str(errors[0])
    proxy.shutdown()
    for fn in (lambda: proxy.show(0), lambda: proxy.show(None), proxy.close):
        t = threading.Thread(target=call, args=(fn,))
        t.start()
        t.join(5)
        assert not t.is_alive()
    assert len(errors) == 2 and "closed" in str(errors[1])  # show(None) and close are ignored: the owner closes
    assert not win.closed
    proxy.request_stop()
    assert proxy.stop_requested  # any thread may ask the window to stop


def test_hand_over_wraps_only_thread_bound_projectors():
    hand_over = HandOver()
    plain = WindowLike()
    plain.thread_bound = False  # e.g. the virtual rig's projector: any thread may call it
    assert hand_over(plain) is plain and hand_over.proxy is None
    win = WindowLike()
    wrapped = hand_over(win)
    assert isinstance(wrapped, OwnerThreadProjector) and hand_over.proxy is wrapped
    hand_over.finish()
    assert win.closed and hand_over.proxy is None
