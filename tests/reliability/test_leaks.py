"""Sessions started and stopped one after another (the view's scheme switch, a bench that loops)
leave no thread and no file descriptor behind, also when a session ends on a device fault."""

from __future__ import annotations

import threading
import time

from app.bench.soak import open_fds
from app.live_pipeline import LivePipeline

from .conftest import fresh_devices, make_loop


def _settle(baseline_threads: int, deadline_s: float = 5.0) -> int:
    end = time.monotonic() + deadline_s
    while threading.active_count() > baseline_threads and time.monotonic() < end:
        time.sleep(0.05)
    return threading.active_count()


def test_repeated_sessions_leak_no_threads_or_fds(rig_session):
    session, processor = rig_session
    faults = [None, [{"kind": "disappear", "at": [12]}], [{"kind": "drop", "probability": 0.05}]]
    # one warm-up session: first-use imports and numba compilation are not leaks
    first = LivePipeline(lambda: make_loop(session, fresh_devices(session)), processor, max_frames=10)
    first.start()
    first.wait()
    threads0, fds0 = _settle(threading.active_count()), open_fds()
    names0 = sorted(t.name for t in threading.enumerate())
    errors = []
    for k in range(6):
        dev = fresh_devices(session, faults[k % 3], seed=k)
        pipe = LivePipeline(lambda dev=dev: make_loop(session, dev, timeout_s=1.0), processor, max_frames=24)
        pipe.start()
        pipe.wait()
        errors.append(pipe.error)
        assert _settle(threads0) == threads0, sorted(t.name for t in threading.enumerate())
        assert open_fds() <= fds0, (k, open_fds(), fds0)
    assert sorted(t.name for t in threading.enumerate()) == names0
    assert sum(1 for e in errors if e and "disappeared" in e) == 2  # the faulty sessions did end on their fault


def test_repeated_sessions_on_the_serial_trigger_box_leak_nothing(rig_session, tmp_path):
    from drivers.trigger.emulator import TriggerBoxEmulator
    from drivers.trigger.serial_box import SerialTriggerBox

    from .test_faults import VsyncBridge

    session, processor = rig_session
    with TriggerBoxEmulator(link=tmp_path / "ttyTRIG") as emu:
        baseline = None
        for k in range(4):
            dev = fresh_devices(session, stepped=True, seed=k)
            trig = SerialTriggerBox(str(emu.port), cycle=2, source="ext", timeout_s=1.0)
            with VsyncBridge(emu, dev):
                pipe = LivePipeline(lambda d=dev, t=trig: make_loop(session, d, trigger=t), processor, max_frames=20)
                pipe.start()
                pipe.wait()
            assert pipe.error is None, pipe.error
            trig.close()  # CaptureLoop.close closed it already: a second close is harmless
            now = (_settle(baseline[0]) if baseline else threading.active_count(), open_fds())
            if baseline is None:
                baseline = now  # after the first session: imports and compilation done
            assert now[0] <= baseline[0] and now[1] <= baseline[1], (k, now, baseline, threading.enumerate())
