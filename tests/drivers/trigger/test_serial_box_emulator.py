"""The pyserial driver against the Python emulator, over a real pseudo-terminal pair."""

from __future__ import annotations

import itertools
import time

import pytest
import serial

from core.errors import DeviceError, InputError
from drivers.base import TRIGGERS, Trigger
from drivers.trigger import protocol as proto
from drivers.trigger.emulator import TriggerBoxEmulator
from drivers.trigger.errors import (
    TriggerCommandError,
    TriggerDisconnectedError,
    TriggerPortError,
    TriggerProtocolError,
    TriggerResetError,
    TriggerTimeoutError,
)
from drivers.trigger.serial_box import SerialTriggerBox

WAIT = 3.0  # for events that must come: generous, a loaded machine can stall a pty for a second


def open_box(port: str, **kw) -> SerialTriggerBox:
    kw.setdefault("boot_wait_s", 1.0)
    kw.setdefault("timeout_s", 2.0)  # a retry would change the bytes on the line
    return SerialTriggerBox(port, **kw)


def test_registered_and_implements_trigger(emulator):
    assert TRIGGERS["serial"] is SerialTriggerBox
    with TRIGGERS["serial"](port=emulator.port, boot_wait_s=1.0) as box:
        assert isinstance(box, Trigger)
        assert box.version == "1.0" and box.boot_id == emulator.boot_id


def test_bytes_the_driver_puts_on_the_line(emulator):
    with open_box(emulator.port, cycle=2, source="int", pulse_us=200) as box:
        box.start(59.94)
        box.stop()
    assert bytes(emulator.rx) == (
        b"$VER*41\n$STOP*18\n$CYC,2*47\n$SRC,INT*3D\n$PW,200*19\n$RATE,59.940*31\n$START*40\n$STOP*18\n"
    )
    # and every line the box sent back is framed and checksummed
    lines = list(proto.LineDecoder().feed(bytes(emulator.tx)))
    assert all(isinstance(x, proto.Line) for x in lines)
    assert [x.fields[:2] for x in lines if x.name == "OK"] == [
        ("OK", c) for c in ("VER", "STOP", "CYC", "SRC", "PW", "RATE", "START", "STOP")
    ]


def test_events_count_and_mark_each_pattern_cycle(emulator):
    with open_box(emulator.port, cycle=3) as box:
        box.start(200)
        assert box.active_source == "INT"
        events = [box.next_event(WAIT) for _ in range(30)]
        assert [e.count for e in events] == list(range(1, 31))
        assert [e.phase for e in events] == [0, 1, 2] * 10
        assert all(a.host_timestamp_ns <= b.host_timestamp_ns for a, b in itertools.pairwise(events))
        assert box.counter() >= 30
        assert box.missed_events == 0
        # restart: the counter and the phase start again, and no old event leaks into the new run
        box.start(200)
        first = box.next_event(WAIT)
        assert (first.count, first.phase) == (1, 0)


def test_open_a_box_left_running_by_another_session(emulator):
    with serial.Serial(emulator.port, proto.BAUD) as other:  # a previous session started it and went away
        other.write(proto.encode("CYC", 3) + proto.encode("START"))
        time.sleep(0.1)
    assert emulator.running and emulator.count > 0
    with open_box(emulator.port, cycle=2) as box:  # a different cycle: its old events must not count
        time.sleep(0.1)
        assert box.drain_events() == []
        box.start(100)
        events = [box.next_event(WAIT) for _ in range(4)]
        assert [(e.count, e.phase) for e in events] == [(1, 0), (2, 1), (3, 0), (4, 1)]
        assert box.missed_events == 0


def test_resync_after_garbage_between_events(emulator):
    with open_box(emulator.port) as box:
        box.start(100)
        box.next_event(WAIT)
        emulator.inject(b"\x00\xff$T,99,0*00\n$OK,CN\r\nnoise noise $$$***\n")
        box.next_event(WAIT)  # the line is still usable
        emulator.inject(b"$T,5")  # a half line, completed by nothing: the next '$' resyncs
        events = [box.next_event(WAIT) for _ in range(10)]
        counts = [e.count for e in events]
        assert counts == list(range(counts[0], counts[0] + 10))
        assert box.missed_events == 0
        assert box.garbage_bytes > 30
        assert box.counter() >= counts[-1]


def test_phase_mismatch_is_a_protocol_error(emulator):
    with open_box(emulator.port, cycle=2) as box:
        box.start(100)
        box.next_event(WAIT)
        emulator.swap_phases()
        with pytest.raises(TriggerProtocolError, match="phase") as exc:
            for _ in range(10):
                box.next_event(WAIT)
        assert emulator.port in str(exc.value)
        with pytest.raises(TriggerProtocolError):  # it stays an error until the next start
            box.next_event(WAIT)


def test_reset_mid_session_is_detected_from_the_boot_line(emulator):
    with open_box(emulator.port) as box:
        box.start(100)
        box.next_event(WAIT)
        boot0 = box.boot_id
        emulator.reset()
        t0 = time.monotonic()
        with pytest.raises(TriggerResetError, match="rebooted") as exc:
            for _ in range(100):
                box.next_event(WAIT)
        assert time.monotonic() - t0 < WAIT  # at the BOOT line, not at a timeout
        assert emulator.port in str(exc.value) and "\n" not in str(exc.value)
        assert box.boot_id == boot0 + 1
        box.start(100)  # the operator restarts: the box is configured again (it lost its settings)
        assert box.next_event(WAIT).count == 1
        assert emulator.cycle == 2 and emulator.running


def test_silent_reset_is_detected_by_boot_id_and_counter(emulator):
    with open_box(emulator.port) as box:
        box.start(100)
        for _ in range(5):
            ev = box.next_event(WAIT)
        emulator.reset(announce=False)  # the BOOT line is lost
        with pytest.raises(TriggerResetError):
            box.counter()  # count went back to 0 (or the boot id changed)
        box.start(100)
        box.next_event(WAIT)
        emulator.reset(announce=False)
        with pytest.raises(TriggerResetError, match=r"boot id|stopped"):
            box.next_event(0.3)  # silence -> STAT -> boot id changed
        assert ev.count == 5


def test_box_that_reboots_as_the_port_opens(emulator):
    emulator.reboot(0.4)  # an Uno resets on DTR: deaf while its bootloader runs, then BOOT
    with open_box(emulator.port, timeout_s=0.2, boot_wait_s=2.0) as box:
        assert box.boot_id == emulator.boot_id
        assert box.counter() == 0  # a reboot while connecting is not a reset mid-session
        box.start(100)
        assert box.next_event(WAIT).count == 1
    assert emulator.rx.count(b"$VER*41\n") >= 1


def test_missing_port_fails_at_once():
    t0 = time.monotonic()
    with pytest.raises(TriggerPortError, match="/dev/ttyNOPE0 does not exist") as exc:
        SerialTriggerBox("/dev/ttyNOPE0")
    assert time.monotonic() - t0 < 0.5  # no waiting at all: the path is checked first
    assert isinstance(exc.value, DeviceError)


def test_busy_port(emulator):
    with open_box(emulator.port), pytest.raises(TriggerPortError, match="busy"):
        open_box(emulator.port)


def test_box_that_never_answers_times_out_quickly(emulator):
    emulator.silent = True
    t0 = time.monotonic()
    with pytest.raises(TriggerTimeoutError, match="does not answer") as exc:
        open_box(emulator.port, boot_wait_s=0.5)
    assert time.monotonic() - t0 < 1.5  # boot_wait_s, plus scheduling slack
    assert emulator.port in str(exc.value)


def test_box_that_answers_garbage(emulator):
    emulator.garbage = True
    t0 = time.monotonic()
    with pytest.raises(TriggerProtocolError, match=r"garbage.*baud"):
        open_box(emulator.port, boot_wait_s=0.5)
    assert time.monotonic() - t0 < 1.5  # boot_wait_s, plus scheduling slack


def test_a_device_that_is_not_a_trigger_box():
    with TriggerBoxEmulator() as emu:
        emu._cmd_ver = lambda name: emu._send("OK", name, "GPSMOD", "2.1", 1)  # answers VER as another product
        with pytest.raises(TriggerProtocolError, match="not an SLTRIG box"):
            open_box(emu.port)


def test_box_stops_answering_mid_session(emulator):
    with open_box(emulator.port, timeout_s=0.2, retries=1) as box:
        box.start(100)
        box.next_event(WAIT)
        emulator.silent = True
        t0 = time.monotonic()
        with pytest.raises(TriggerTimeoutError, match="did not answer STAT"):
            for _ in range(100):
                box.next_event(0.2)
        assert time.monotonic() - t0 < 2.5  # 0.2 s wait + 2 x 0.2 s STAT, plus scheduling slack


def test_refused_commands_are_typed(emulator):
    with open_box(emulator.port) as box:
        with pytest.raises(TriggerCommandError, match=r"refused CYC,17: RANGE") as exc:
            box.command("CYC", 17)
        assert exc.value.code == "RANGE"
        box.start(50)
        with pytest.raises(TriggerCommandError) as exc:
            box.command("PW", 100)
        assert exc.value.code == "BUSY"
        with pytest.raises(TriggerCommandError) as exc:
            box.command("FLY")
        assert exc.value.code == "UNKNOWN"
    with pytest.raises(InputError, match=r"rate 0\.5 Hz"), open_box(emulator.port) as box:
        box.start(0.5)


def test_corrupted_command_is_resent(emulator):
    with open_box(emulator.port) as box:
        sent = []
        real_write = box._ser.write

        def flaky_write(data):  # the first CNT line gets one bit flipped on the wire
            sent.append(data)
            if data.startswith(b"$CNT") and len(sent) == 1:
                data = b"$CNU" + data[4:]
            return real_write(data)

        box._ser.write = flaky_write
        assert box.counter() == 0
        assert sent == [b"$CNT*59\n", b"$CNT*59\n"]  # ERR,?,CHECKSUM -> sent again at once


def test_unplug_then_reconnect(emulator):
    box = open_box(emulator.port)
    try:
        box.start(100)
        box.next_event(WAIT)
        emulator.unplug()
        t0 = time.monotonic()
        with pytest.raises(TriggerDisconnectedError, match="went away"):
            for _ in range(100):
                box.next_event(WAIT)
        assert time.monotonic() - t0 < WAIT  # at the read error, not at a timeout
        emulator.replug()  # new /dev/pts/N behind the same link path
        box.start(100)  # reconnects by itself
        assert box.next_event(WAIT).count == 1
        assert box.boot_id == emulator.boot_id
    finally:
        box.close()
        box.close()  # idempotent


def test_external_vsync_source(emulator):
    with open_box(emulator.port, source="ext", cycle=2) as box:
        box.start(60)
        assert box.active_source == "EXT"
        with pytest.raises(TriggerTimeoutError, match="vsync"):
            box.next_event(0.2)
        for _ in range(3):
            emulator.vsync()
        assert [(e.count, e.phase) for e in (box.next_event(WAIT) for _ in range(3))] == [(1, 0), (2, 1), (3, 0)]


def test_auto_source_picks_vsync_when_wired():
    with TriggerBoxEmulator(vsync_hz=120) as emu, open_box(emu.port, source="auto") as box:
        box.start(60)
        t0 = time.monotonic()
        assert box.active_source == "EXT"
        time.sleep(0.5)
        hz = box.counter() / (time.monotonic() - t0)
        assert 90 < hz < 150  # the vsync's rate (120), not the set 60 Hz


def test_bad_settings_are_input_errors():
    with pytest.raises(InputError, match="cycle 0"):
        SerialTriggerBox("/dev/null", cycle=0)
    with pytest.raises(InputError, match="source"):
        SerialTriggerBox("/dev/null", source="vsync")
