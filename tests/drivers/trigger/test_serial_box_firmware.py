"""The pyserial driver against the real firmware, running under simavr with its UART on a pty.

Besides the serial lines, the simulation logs the TRIG / MARK pins in CPU cycles, so the tests also
check what the camera and the marker input would see.
"""

from __future__ import annotations

import itertools
import time

import pytest

from drivers.trigger.errors import TriggerResetError, TriggerTimeoutError
from drivers.trigger.serial_box import SerialTriggerBox

pytestmark = pytest.mark.simavr
F_CPU = 16_000_000
WAIT = 3.0  # generous: on a loaded 2-core machine the pty path alone can stall for a second


def open_box(port: str, **kw) -> SerialTriggerBox:
    kw.setdefault("boot_wait_s", 3.0)
    kw.setdefault("timeout_s", 2.0)
    return SerialTriggerBox(port, **kw)


def test_events_counter_and_pins(simbox):
    with open_box(simbox.port, cycle=3, pulse_us=100, source="int") as box:
        assert box.version == "1.0" and box.boot_id == 0
        assert box.counter() == 0  # its BOOT line (sent as we connected) is not a reset mid-session
        box.start(100)
        assert box.active_source == "INT"
        events = [box.next_event(WAIT) for _ in range(30)]
        box.stop()
        fired = box.counter()
        assert box.missed_events == 0
    assert [e.count for e in events] == list(range(1, 31))
    assert [e.phase for e in events] == [0, 1, 2] * 10

    edges, _ = simbox.edges()
    rises = [e for e in edges if e.trig == 1]
    falls = [e for e in edges if e.trig == 0]
    assert len(rises) == fired >= 30  # one pulse per count, none unreported
    assert [e.mark for e in rises] == [int(i % 3 == 0) for i in range(fired)]  # MARK starts each cycle
    assert all(e.mark == 0 for e in falls)
    widths = [f.cycle - r.cycle for r, f in zip(rises, falls, strict=False)]
    assert all(abs(w - 100 * 16) <= 4 * 16 for w in widths), widths  # 100 us, 4 us steps
    periods = [b.cycle - a.cycle for a, b in itertools.pairwise(rises)]
    assert all(abs(p - F_CPU // 100) <= 16 for p in periods), periods  # 10 ms, one tick of jitter


def test_fractional_rate_is_exact_in_crystal_time(simbox):
    with open_box(simbox.port, source="int") as box:
        box.start(59.94)
        for _ in range(40):
            box.next_event(WAIT)
        box.stop()
    rises = [e.cycle for e in simbox.edges()[0] if e.trig]
    exact = F_CPU / 59.94  # 266933.6 cycles: not a whole number of timer ticks
    periods = [b - a for a, b in itertools.pairwise(rises)]
    assert {round(p / 8) for p in periods} == {33366, 33367}  # two period lengths, 0.5 us ticks
    mean = (rises[-1] - rises[0]) / (len(rises) - 1)
    assert abs(mean - exact) < 0.5, (mean, exact)  # < 2 ppm over 40 periods


def test_projector_vsync_drives_the_trigger(simbox_factory):
    vsync_hz = 75.0
    sim = simbox_factory(vsync_hz=vsync_hz)
    period = round(F_CPU / vsync_hz)
    with open_box(sim.port, cycle=2, source="auto") as box:
        box.start(30)  # the rate is only the fallback: a wired vsync wins
        assert box.active_source == "EXT"
        events = [box.next_event(WAIT) for _ in range(12)]
        box.stop()
    assert [(e.count, e.phase) for e in events] == [(i, (i - 1) % 2) for i in range(1, 13)]
    rises = [e.cycle for e in sim.edges()[0] if e.trig]
    assert all((c % period) < 16 * 10 for c in rises), [c % period for c in rises]  # within 10 us of vsync
    assert all(abs((b - a) - period) < 16 * 10 for a, b in itertools.pairwise(rises))


def test_no_vsync_falls_back_to_the_timer(simbox):
    with open_box(simbox.port, source="auto") as box:
        box.start(50)
        assert box.active_source == "INT"
        assert box.next_event(WAIT).count == 1


def test_power_glitch_mid_session_is_detected(simbox):
    with open_box(simbox.port) as box:
        box.start(100)
        box.next_event(WAIT)
        simbox.reset()
        t0 = time.monotonic()
        with pytest.raises(TriggerResetError, match="rebooted") as exc:
            for _ in range(200):
                box.next_event(WAIT)
        assert time.monotonic() - t0 < WAIT
        assert simbox.port in str(exc.value)
        assert box.boot_id == 1  # the EEPROM boot counter moved on
        box.start(100)
        assert box.next_event(WAIT).count == 1


def test_reset_command_and_boot_id(simbox):
    with open_box(simbox.port) as box:
        box.reset_box()
        assert box.boot_id == 1
        box.start(100)
        assert box.next_event(WAIT).count == 1
        assert box.status()["boot_id"] == 1


def test_hung_box_times_out_then_recovers(simbox):
    with open_box(simbox.port, timeout_s=0.2, retries=1) as box:
        box.start(100)
        box.next_event(WAIT)
        simbox.pause()
        try:
            t0 = time.monotonic()
            with pytest.raises(TriggerTimeoutError, match="did not answer"):
                for _ in range(200):
                    box.next_event(0.2)
            assert time.monotonic() - t0 < 2.5  # 0.2 s wait + 2 x 0.2 s STAT, plus scheduling
        finally:
            simbox.resume()
        assert box.counter() > 0  # it answers again


def test_host_garbage_does_not_disturb_the_running_box(simbox):
    with open_box(simbox.port) as box:
        box.start(100)
        box.next_event(WAIT)
        box._ser.write(b"\x00\xff\xfe$$$ST\x13OP*\n$STOP*00\nxx$CY")  # line noise towards the box
        events = [box.next_event(WAIT) for _ in range(10)]
        counts = [e.count for e in events]
        assert counts == list(range(counts[0], counts[0] + 10))  # still running, nothing lost
        assert box.status()["running"]
