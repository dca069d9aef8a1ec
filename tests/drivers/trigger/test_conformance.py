"""Exact bytes on the line: the firmware (under simavr) and the emulator answer the same script the same way.

The expected replies are written out here from PROTOCOL.md, with the checksum computed independently.
"""

from __future__ import annotations

import re
import time
from functools import reduce

import pytest
import serial

from drivers.trigger import protocol as proto


def framed(body: str) -> bytes:
    b = body.encode()
    return b"$" + b + b"*%02X\n" % reduce(lambda a, c: a ^ c, b, 0)


# (bytes sent, expected reply body or None for "no reply"); "#" matches a decimal number
SCRIPT: list[tuple[bytes, str | None]] = [
    (b"$VER*41\n", "OK,VER,SLTRIG,1.0,{boot}"),
    (b"$ver\n", "OK,VER,SLTRIG,1.0,{boot}"),  # typed by hand: no checksum, lower case
    (b"\x00\xffnoise$VE$VER*41\r\n", "OK,VER,SLTRIG,1.0,{boot}"),  # garbage, a torn line, CRLF
    (b"$VER*42\n", "ERR,?,CHECKSUM"),
    (b"$VER*4\n", "ERR,?,CHECKSUM"),
    (b"$" + b"A" * 70 + b"\n", "ERR,?,LONG"),
    (b"$VE\x01R*41\n", None),  # a control byte inside a line: dropped silently
    (framed("FLY"), "ERR,FLY,UNKNOWN"),
    (b"$abcdefghijklmnop\n", "ERR,ABCDEFGHIJKL,UNKNOWN"),
    (framed("RATE"), "ERR,RATE,ARG"),
    (framed("RATE,abc"), "ERR,RATE,ARG"),
    (framed("RATE,60."), "ERR,RATE,ARG"),
    (framed("RATE,1.5,2"), "ERR,RATE,ARG"),
    (framed("RATE,0.999"), "ERR,RATE,RANGE"),
    (framed("RATE,250.001"), "ERR,RATE,RANGE"),
    (framed("RATE,59.94"), "OK,RATE,59.940"),
    (framed("CYC,0"), "ERR,CYC,RANGE"),
    (framed("CYC,x"), "ERR,CYC,ARG"),
    (framed("CYC,3"), "OK,CYC,3"),
    (framed("PW,7"), "ERR,PW,RANGE"),
    (framed("PW,102"), "OK,PW,100"),
    (framed("SRC,XYZ"), "ERR,SRC,ARG"),
    (framed("SRC,int"), "OK,SRC,INT"),
    (framed("STAT"), "OK,STAT,0,INT,-,59.940,3,100,0,{boot}"),
    (framed("START"), "OK,START,INT"),
    (framed("CYC,2"), "ERR,CYC,BUSY"),
    (framed("SRC,EXT"), "ERR,SRC,BUSY"),
    (framed("PW,50"), "ERR,PW,BUSY"),
    (framed("RATE,100"), "OK,RATE,100.000"),
    (framed("STAT"), "OK,STAT,1,INT,INT,100.000,3,100,#,{boot}"),
    (framed("STOP"), "OK,STOP,#"),
    (framed("STOP"), "OK,STOP,#"),
    (framed("CNT"), "OK,CNT,#"),
]


def wait_ready(s: serial.Serial) -> None:
    """Until the box answers VER (the firmware may still be booting); then drop what came so far."""
    dec = proto.LineDecoder()
    for _ in range(100):
        s.write(b"$VER*41\n")
        time.sleep(0.02)
        if any(isinstance(x, proto.Line) and x.name == "OK" for x in dec.feed(s.read(4096))):
            break
    time.sleep(0.05)
    s.reset_input_buffer()


def converse(port: str) -> tuple[list[list[bytes]], list[proto.Line]]:
    """Play SCRIPT; return the reply lines to each step (event lines set aside) and the event lines."""
    replies, events = [], []
    with serial.Serial(port, proto.BAUD, timeout=0.02) as s:
        wait_ready(s)
        dec = proto.LineDecoder()
        for data, expect in SCRIPT:
            s.write(data)
            got: list[bytes] = []
            deadline = time.monotonic() + (0.15 if expect is None else 3.0)
            while time.monotonic() < deadline and (expect is None or not got):
                for item in dec.feed(s.read(s.in_waiting or 1)):
                    if isinstance(item, proto.Line) and item.name == "T":
                        events.append(item)
                    else:
                        got.append(item.raw)
            replies.append(got)
    return replies, events


def check(replies: list[list[bytes]], boot: int) -> None:
    for (sent, expect), got in zip(SCRIPT, replies, strict=True):
        if expect is None:
            assert got == [], f"{sent!r} -> {got!r}, expected no reply"
            continue
        body = expect.format(boot=boot)
        want = re.escape(body).replace("\\#", r"\d+").replace("\\*", r"\*")
        assert len(got) == 1, f"{sent!r} -> {got!r}"
        m = re.fullmatch(rb"\$(.*)\*([0-9A-F]{2})\n", got[0])
        assert m and re.fullmatch(want, m.group(1).decode()), f"{sent!r} -> {got[0]!r}, expected {body!r}"
        assert got[0] == framed(m.group(1).decode()), f"bad checksum in {got[0]!r}"


def check_events(events: list[proto.Line], cycle: int) -> None:
    counts = [int(e.fields[1]) for e in events]
    assert counts == list(range(1, len(counts) + 1))
    assert [int(e.fields[2]) for e in events] == [(c - 1) % cycle for c in counts]


@pytest.mark.simavr
def test_firmware_speaks_the_protocol(simbox):
    replies, events = converse(simbox.port)
    check(replies, boot=0)  # a fresh simulated EEPROM: boot id 0
    check_events(events, 3)


def test_emulator_speaks_the_protocol(emulator):
    replies, events = converse(emulator.port)
    check(replies, boot=emulator.boot_id)
    check_events(events, 3)


def reset_exchange(port: str) -> list[proto.Line]:
    with serial.Serial(port, proto.BAUD, timeout=0.05) as s:
        wait_ready(s)
        s.write(framed("RESET"))
        dec, lines = proto.LineDecoder(), []
        deadline = time.monotonic() + 5.0
        while len(lines) < 2 and time.monotonic() < deadline:
            lines += [x for x in dec.feed(s.read(256)) if isinstance(x, proto.Line)]
        s.write(framed("VER"))
        while len(lines) < 3 and time.monotonic() < deadline:
            lines += [x for x in dec.feed(s.read(256)) if isinstance(x, proto.Line)]
    return lines


@pytest.mark.simavr
def test_firmware_reset_command_reboots_through_the_watchdog(simbox):
    lines = reset_exchange(simbox.port)
    assert [x.raw for x in lines] == [
        framed("OK,RESET"),
        framed("BOOT,SLTRIG,1.0,1,WDT"),  # the boot counter in EEPROM survived the reset
        framed("OK,VER,SLTRIG,1.0,1"),
    ]


def test_emulator_reset_command(emulator):
    b = emulator.boot_id
    assert [x.raw for x in reset_exchange(emulator.port)] == [
        framed("OK,RESET"),
        framed(f"BOOT,SLTRIG,1.0,{b + 1},WDT"),
        framed(f"OK,VER,SLTRIG,1.0,{b + 1}"),
    ]
