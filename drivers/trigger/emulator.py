"""A trigger box in Python, on a real pseudo-terminal: speaks PROTOCOL.md like the firmware does.

The driver opens `emulator.port` with pyserial exactly as it would open /dev/ttyACM0. Fault hooks
for reliability tests: `reset()` (reboot mid-session), `inject()` (garbage on the line),
`silent` (stops answering), `garbage` (answers noise), `unplug()` / `replug()` (port vanishes and
comes back under the same `link` path).

    with TriggerBoxEmulator(link=tmp / "ttyTRIG") as box:
        trig = SerialTriggerBox(str(box.port))
"""

from __future__ import annotations

import contextlib
import os
import random
import select
import threading
import time
import tty
from pathlib import Path

from drivers.trigger import protocol as proto

FW_VERSION = "1.0"


class TriggerBoxEmulator:
    def __init__(self, link: str | os.PathLike | None = None, boot_id: int = 1, vsync_hz: float | None = None) -> None:
        self.link = Path(link) if link is not None else None
        self.boot_id = boot_id
        self.vsync_hz = vsync_hz  # a projector vsync wired to the box, or None
        self.rx = bytearray()  # every byte the host sent
        self.tx = bytearray()  # every byte the box sent
        self.silent = False
        self.garbage = False
        self.phase_fault = False
        self._booting_until = 0.0
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._decoder = proto.LineDecoder(require_checksum=False)
        self._wake_r, self._wake_w = os.pipe()
        self._defaults()
        self._open_pty()
        self._thread = threading.Thread(target=self._run, name="trigger-emulator", daemon=True)
        self._thread.start()

    # -- state ------------------------------------------------------------------------------
    def _defaults(self) -> None:
        self.running = False
        self.source = "AUTO"
        self.active = "-"
        self.rate_mhz = 60_000
        self.cycle = 2
        self.pulse_us = 100
        self.count = 0
        self._next_fire = 0.0

    def _open_pty(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing, like a UART
        self.slave_name = os.ttyname(self._slave)
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".new")
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
            tmp.symlink_to(self.slave_name)
            tmp.replace(self.link)

    @property
    def port(self) -> str:
        return str(self.link) if self.link is not None else self.slave_name

    # -- fault hooks ------------------------------------------------------------------------
    def reset(self, cause: str = "PWR", announce: bool = True) -> None:
        """Reboot: stopped, counter 0, settings back to defaults, boot id + 1, BOOT line."""
        with self._lock:
            self._defaults()
            self.boot_id += 1
            self._decoder = proto.LineDecoder(require_checksum=False)
            if announce:
                self._send("BOOT", proto.PRODUCT, FW_VERSION, self.boot_id, cause)
        self._wake()

    def reboot(self, boot_s: float = 0.3) -> None:
        """Like an Uno reset by DTR when the port opens: deaf for boot_s (the bootloader), then BOOT."""
        with self._lock:
            self._defaults()
            self._booting_until = time.monotonic() + boot_s
        self._wake()

    def inject(self, data: bytes) -> None:
        """Raw bytes to the host, e.g. line noise."""
        with self._lock:
            self._write(data)

    def unplug(self) -> None:
        """The USB cable is pulled: the port stops existing (the host's reads fail)."""
        with self._lock:
            self._defaults()
            for fd in (self._master, self._slave):
                with contextlib.suppress(OSError):
                    os.close(fd)
            self._master = self._slave = -1
            if self.link is not None:
                with contextlib.suppress(FileNotFoundError):
                    self.link.unlink()
        self._wake()

    def replug(self) -> None:
        """Plugged back: a new pty (new /dev/pts/N), the same `link`; the box has rebooted."""
        with self._lock:
            self.boot_id += 1
            self._decoder = proto.LineDecoder(require_checksum=False)
            self._open_pty()
        self._wake()

    def swap_phases(self, on: bool = True) -> None:
        """A box whose cycle marking is off by one (the fault that inverts a two-shot pair)."""
        with self._lock:
            self.phase_fault = on

    def vsync(self) -> None:
        """One projector vsync edge (only fires when running with the EXT source)."""
        with self._lock:
            if self.running and self.active == "EXT":
                self._fire()

    # -- life -------------------------------------------------------------------------------
    def close(self) -> None:
        self._stop.set()
        self._wake()
        self._thread.join(2.0)
        with self._lock:
            for fd in (self._master, self._slave, self._wake_r, self._wake_w):
                if fd >= 0:
                    with contextlib.suppress(OSError):
                        os.close(fd)
            self._master = self._slave = -1
            if self.link is not None and self.link.is_symlink():
                self.link.unlink()

    def __enter__(self) -> TriggerBoxEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals --------------------------------------------------------------------------
    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _write(self, data: bytes) -> None:
        if self._master < 0:
            return
        self.tx += data
        with contextlib.suppress(OSError):
            os.write(self._master, data)

    def _send(self, *fields: object) -> None:
        if self.silent:
            return
        if self.garbage:
            self._write(bytes(random.randrange(256) for _ in range(12)).replace(b"$", b"#") + b"\n")
            return
        self._write(proto.encode(*fields))

    def _period_s(self) -> float:
        return 1000.0 / self.rate_mhz

    def _fire(self) -> None:
        self.count += 1
        self._send("T", self.count, (self.count - 1 + self.phase_fault) % self.cycle)

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                fd = self._master
                timeout = 0.05
                if self.running and self.active == "INT":
                    timeout = max(0.0, self._next_fire - time.monotonic())
                elif self.running and self.active == "EXT" and self.vsync_hz:
                    timeout = max(0.0, self._next_fire - time.monotonic())
            fds = [self._wake_r] + ([fd] if fd >= 0 else [])
            try:
                readable, _, _ = select.select(fds, [], [], min(timeout, 0.05))
            except (OSError, ValueError):
                readable = []
            if self._wake_r in readable:
                os.read(self._wake_r, 4096)
            with self._lock:
                if fd >= 0 and fd == self._master and fd in readable:
                    try:
                        data = os.read(fd, 4096)
                    except OSError:
                        data = b""
                    if self._booting_until:
                        data = b""  # the bootloader does not speak our protocol
                    if not self.silent:
                        self.rx += data
                        for item in self._decoder.feed(data):
                            self._handle(item)
                if self._booting_until and time.monotonic() >= self._booting_until:
                    self._booting_until = 0.0
                    self.reset(cause="EXT")
                self._tick()

    def _tick(self) -> None:
        """Fire every period that has come due (timer, or the emulated vsync generator)."""
        timed = self.active == "INT" or (self.active == "EXT" and self.vsync_hz)
        if not self.running or not timed:
            return
        period = self._period_s() if self.active == "INT" else 1.0 / float(self.vsync_hz or 1)
        now = time.monotonic()
        while self._next_fire <= now:
            self._fire()
            self._next_fire += period

    def _handle(self, item: proto.Line | proto.BadLine) -> None:
        if isinstance(item, proto.BadLine):
            self._send("ERR", "?", item.reason)
            return
        name, args = item.name.upper(), item.fields[1:]
        handler = {
            "VER": self._cmd_ver,
            "RATE": self._cmd_rate,
            "CYC": self._cmd_cyc,
            "SRC": self._cmd_src,
            "PW": self._cmd_pw,
            "START": self._cmd_start,
            "STOP": self._cmd_stop,
            "CNT": self._cmd_cnt,
            "STAT": self._cmd_stat,
            "RESET": self._cmd_reset,
        }.get(name)
        if handler is None:
            self._send("ERR", name[:12], "UNKNOWN")
            return
        nargs = 1 if name in ("RATE", "CYC", "SRC", "PW") else 0
        if len(args) != nargs:
            self._send("ERR", name, "ARG")
            return
        handler(name, *args)

    def _cmd_ver(self, name: str) -> None:
        self._send("OK", name, proto.PRODUCT, FW_VERSION, self.boot_id)

    def _cmd_rate(self, name: str, arg: str) -> None:
        mhz = proto.parse_rate(arg)
        if mhz is None:
            return self._send("ERR", name, "ARG")
        if not proto.RATE_MIN_MHZ <= mhz <= proto.RATE_MAX_MHZ:
            return self._send("ERR", name, "RANGE")
        self.rate_mhz = mhz
        if self.running and self.active == "INT":  # like the firmware: the period restarts now
            self._next_fire = time.monotonic() + self._period_s()
        self._send("OK", name, proto.format_rate(mhz))

    def _int_arg(self, name: str, arg: str, lo: int, hi: int) -> int | None:
        if not arg.isdigit() or not arg.isascii() or len(arg) > 6:
            self._send("ERR", name, "ARG")
            return None
        if not lo <= int(arg) <= hi:
            self._send("ERR", name, "RANGE")
            return None
        if self.running:
            self._send("ERR", name, "BUSY")
            return None
        return int(arg)

    def _cmd_cyc(self, name: str, arg: str) -> None:
        n = self._int_arg(name, arg, proto.CYC_MIN, proto.CYC_MAX)
        if n is not None:
            self.cycle = n
            self._send("OK", name, n)

    def _cmd_pw(self, name: str, arg: str) -> None:
        us = self._int_arg(name, arg, proto.PW_MIN_US, proto.PW_MAX_US)
        if us is not None:
            self.pulse_us = us // 4 * 4
            self._send("OK", name, self.pulse_us)

    def _cmd_src(self, name: str, arg: str) -> None:
        if arg.upper() not in proto.SOURCES:
            return self._send("ERR", name, "ARG")
        if self.running:
            return self._send("ERR", name, "BUSY")
        self.source = arg.upper()
        self._send("OK", name, self.source)

    def _cmd_start(self, name: str) -> None:
        self.active = self.source if self.source != "AUTO" else ("EXT" if self.vsync_hz else "INT")
        self.running, self.count = True, 0
        now = time.monotonic()
        self._next_fire = now + (self._period_s() if self.active == "INT" else 1.0 / float(self.vsync_hz or 1))
        self._send("OK", name, self.active)

    def _cmd_stop(self, name: str) -> None:
        self.running, self.active = False, "-"
        self._send("OK", name, self.count)

    def _cmd_cnt(self, name: str) -> None:
        self._send("OK", name, self.count)

    def _cmd_stat(self, name: str) -> None:
        self._send(
            "OK",
            name,
            int(self.running),
            self.source,
            self.active,
            proto.format_rate(self.rate_mhz),
            self.cycle,
            self.pulse_us,
            self.count,
            self.boot_id,
        )

    def _cmd_reset(self, name: str) -> None:
        self._send("OK", name)
        self.reset(cause="WDT")
