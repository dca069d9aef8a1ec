"""Fault injection on the virtual rig and the emulated serial trigger box, through the live pipeline.

Each test: the session keeps running (or stops cleanly with a one-line message), no decoded set
is mispaired against the rig's truth of what it showed, and the counters say what happened.

Already covered in tests/app/live (not repeated here): fixed drops/duplicates/swaps/late flips
through the pipeline, a camera that disappears (pipeline level), the virtual trigger resetting,
a camera stall longer than the timeout, the projector window closed. Here: a 2 s stall that
resumes, random faults of every kind with recording on, the serial trigger box (emulator on a
pty) that reboots mid-session or gets garbage on its line or answers only noise, and a camera
that disappears during `slscan dump`.
"""

from __future__ import annotations

import threading
import time

import pytest
import yaml

from app.cli import main
from app.config import DEFAULT_CONFIG
from app.live_pipeline import LivePipeline
from app.recorder import Recorder
from core.dump import DumpWriter, read_dump
from drivers.trigger.emulator import TriggerBoxEmulator
from drivers.trigger.serial_box import SerialTriggerBox

from .conftest import fresh_devices, make_loop, mispaired


def run(session, processor, loop_factory, frames: int, recorder=None):
    results = []
    pipe = LivePipeline(loop_factory, processor, max_frames=frames, recorder=recorder, on_result=results.append)
    pipe.start()
    pipe.wait()
    return pipe, [r.frameset for r in results]


def test_camera_stalls_2s_then_resumes(rig_session):
    session, processor = rig_session
    # the first of ticks 20..59 the camera delivers stalls; after it the camera is ~120 ticks ahead
    # and skips past the rest (a loaded machine may skip tick 20 itself), so ids > 120 come after it
    dev = fresh_devices(session, [{"kind": "stall", "at": list(range(20, 60)), "seconds": 2.0}])
    results = []

    def collect(res) -> None:
        results.append(res)
        if sum(1 for r in results if min(r.frameset.frame_ids) > 120) >= 5:
            pipe.stop()  # pairing and decoding resumed after the stall: enough seen

    t0 = time.monotonic()
    pipe = LivePipeline(lambda: make_loop(session, dev, timeout_s=3.0), processor, max_frames=1500, on_result=collect)
    pipe.start()
    pipe.wait()
    assert time.monotonic() - t0 >= 2.0
    assert pipe.error is None  # 2 s < the 3 s timeout: the session went on
    # ~120 ticks passed during the stall; the camera kept its last 8 frames, the rest show as a gap
    assert pipe.capture.dropped >= 100, pipe.capture
    sets = [r.frameset for r in results]
    assert mispaired(dev, sets) == []
    assert sum(1 for fs in sets if min(fs.frame_ids) > 120) >= 5, pipe.capture


@pytest.fixture(scope="module")
def faulty_recording(rig_session, tmp_path_factory):
    """300 frames with drops, duplicates, swaps and late flips at random (3 % each), decoded and recorded."""
    session, processor = rig_session
    faults = [{"kind": k, "probability": 0.03} for k in ("drop", "duplicate", "swap", "late_flip")]
    dev = fresh_devices(session, faults, seed=3)
    folder = tmp_path_factory.mktemp("faulty") / "rec"
    rec = Recorder(DumpWriter(folder, session.patterns, calibration=session.calibration))
    pipe, sets = run(session, processor, lambda: make_loop(session, dev), frames=300, recorder=rec)
    return dev, pipe, sets, rec.close(), read_dump(folder)


def test_random_faults_of_every_kind_are_counted_and_never_decoded(faulty_recording):
    dev, pipe, sets, stats, dump = faulty_recording
    assert pipe.error is None
    cap = pipe.capture
    # every fault kind happened and was counted; every frame is either tagged or refused once
    assert cap.dropped > 0 and cap.duplicates > 0 and cap.out_of_order > 0 and cap.mistagged > 0, cap
    assert cap.tagged + cap.refused == cap.frames == 300
    assert pipe.stats.decoded >= 20
    assert mispaired(dev, sets) == []
    # the recording holds every frame whose tag was confirmed, once (unconfirmed ones are counted, not written)
    assert stats.lost == 0 and len(dump.frames) == cap.confirmed and 0.5 * cap.tagged < cap.confirmed <= cap.tagged
    ids = [f.frame_id for f in dump.frames]
    assert len(set(ids)) == len(ids)  # a duplicated frame is not recorded twice


def test_recorded_tags_are_what_the_rig_showed(faulty_recording):
    """A frame whose tag the pixel check could not confirm (right after a gap or a refused frame) may
    have seen a late flip: were it recorded, an offline decode of the dump would pair it. (Found by
    this test; fixed in app/capture.py by recording confirmed frames only.)"""
    dev, _, _, _, dump = faulty_recording
    wrong = [(f.frame_id, f.pattern, dev.camera.truth(f.frame_id)) for f in dump.frames]
    wrong = [w for w in wrong if w[1] != w[2]]
    assert wrong == [], f"(frame id, recorded tag, pattern really shown): {wrong}"


# ------------------------------------------------------------------------------------ serial trigger box


class VsyncBridge:
    """The projector's vsync wired to the trigger box (source ext): each edge steps the virtual rig's
    clock and fires the emulated box together, under the emulator's lock, so the box's count (read
    by the capture loop over the serial line) and the rig's tick never disagree. When the box
    restarts its count, the rig's trigger count restarts too (what a camera triggered by it sees)."""

    def __init__(self, emu: TriggerBoxEmulator, dev, period_s: float = 0.016) -> None:
        self.emu, self.dev, self.period_s = emu, dev, period_s
        self.edges = 0
        self.reset_now = False  # reboot the box at the next edge
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> VsyncBridge:
        self.dev.trigger.start(60)  # the rig's stepped clock runs; ticks only come from here
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _run(self) -> None:
        emu, bench = self.emu, self.dev.camera.bench
        while not self._stop.is_set():
            time.sleep(self.period_s)
            with emu._lock:
                if not (emu.running and emu.active == "EXT"):
                    continue
                self.edges += 1
                if self.reset_now:
                    self.reset_now = False
                    emu.reset()  # counter back to 0, stopped, BOOT line
                    continue
                with bench.cond:
                    if emu.count == 0:
                        bench.reset_base = bench.ticks  # a restarted box: trigger counts start again at 1
                self.dev.trigger.step()
                emu.vsync()


@pytest.fixture
def box(tmp_path):
    with TriggerBoxEmulator(link=tmp_path / "ttyTRIG") as emu:
        # 1 s: the emulator's thread shares two loaded cores with the whole session
        trig = SerialTriggerBox(str(emu.port), cycle=2, source="ext", timeout_s=1.0)
        try:
            yield emu, trig
        finally:
            trig.close()


def test_trigger_box_reboots_mid_session(rig_session, box):
    session, processor = rig_session
    emu, trig = box
    dev = fresh_devices(session, stepped=True)
    seen = []

    def reboot_after_60(frame) -> None:
        seen.append(frame)
        if len(seen) == 60:
            bridge.reset_now = True

    with VsyncBridge(emu, dev) as bridge:
        results = []
        pipe = LivePipeline(
            lambda: make_loop(session, dev, trigger=trig),
            processor,
            max_frames=140,
            on_frame=reboot_after_60,
            on_result=results.append,
        )
        pipe.start()
        pipe.wait()
    sets = [r.frameset for r in results]
    assert pipe.error is None, pipe.error  # the loop restarted the box and went on
    cap = pipe.capture
    assert cap.resyncs >= 1 and emu.boot_id == 2
    assert mispaired(dev, sets) == []
    counts = [min(f.trigger_count for f in fs.frames) for fs in sets]
    restarts = [i for i in range(1, len(counts)) if counts[i] < counts[i - 1]]
    assert len(restarts) == 1, counts  # pairs on the old count, then pairs again on the restarted one
    assert restarts[0] >= 5 and len(sets) - restarts[0] >= 5, (counts, cap)


def test_garbage_on_the_serial_line_mid_session(rig_session, box):
    session, processor = rig_session
    emu, trig = box
    dev = fresh_devices(session, stepped=True)
    seen = []
    last_noise = [0]

    def noise(frame) -> None:
        seen.append(frame)
        if len(seen) in (15, 30, 45, 60):
            emu.inject(b"\x00\xff$T,99,0*00\n$OK,CN\r\nnoise $$$***\n$T,5")
            last_noise[0] = frame.frame_id

    with VsyncBridge(emu, dev):
        pipe = LivePipeline(
            lambda: make_loop(session, dev, trigger=trig), processor, max_frames=90, on_frame=noise, on_result=None
        )
        results = []
        pipe.on_result = results.append
        pipe.start()
        pipe.wait()
    assert pipe.error is None, pipe.error
    assert trig.garbage_bytes > 50
    assert pipe.capture.resyncs == 0  # noise is not a reset
    sets = [r.frameset for r in results]
    assert mispaired(dev, sets) == []
    assert len([fs for fs in sets if min(fs.frame_ids) > last_noise[0]]) >= 3  # still pairing after the noise


def test_trigger_box_that_answers_only_noise_stops_the_session_cleanly(rig_session, box):
    session, processor = rig_session
    emu, trig = box
    dev = fresh_devices(session, stepped=True)
    seen = []

    def go_bad(frame) -> None:
        seen.append(frame)
        if len(seen) == 20:
            emu.garbage = True  # a wrong baud rate / a broken line from now on

    with VsyncBridge(emu, dev):
        pipe = LivePipeline(lambda: make_loop(session, dev, trigger=trig), processor, max_frames=10**6, on_frame=go_bad)
        pipe.start()
        pipe.join(20.0)
        stopped = not pipe.running
        pipe.stop()
        pipe.join(5.0)
    assert stopped, "the session did not stop on a trigger box that answers noise"
    assert pipe.error and "\n" not in pipe.error and emu.port in pipe.error, pipe.error
    assert "Traceback" not in pipe.error


def test_camera_disappears_during_slscan_dump(tmp_path, capsys):
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["sim"].update(camera_size=[320, 240], faults=[{"kind": "disappear", "at": [25]}])
    cfg = tmp_path / "gone.yaml"
    cfg.write_text(yaml.safe_dump(data))
    out = tmp_path / "rec"
    code = main(["dump", "--config", str(cfg), "--frames", "1000", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err
    # the banner, then one line that says why it stopped and that the dump is finalised
    assert "disappeared" in err.splitlines()[-1] and "finalised" in err.splitlines()[-1], err
    dump = read_dump(out)  # finalised and readable
    assert 10 <= len(dump.frames) <= 24 and dump.dropped_tail == 0
