"""The serial trigger box driver (PROTOCOL.md) over pyserial: implements drivers.base.Trigger.

A reader thread splits the line into command replies and trigger events. Events carry the
box's count and pattern-cycle phase; the driver checks the phase of every event, counts lost
event lines, and detects a box reset (BOOT line, boot id change, counter going backwards, box
found stopped). Every failure is a TriggerError subclass with a one-line message naming the port.

    box = SerialTriggerBox("/dev/ttyACM0", cycle=2)
    box.start(60)
    ev = box.next_event(timeout_s=0.5)   # TriggerEvent(count, phase, host_timestamp_ns)
"""

from __future__ import annotations

import collections
import contextlib
import errno
import os
import queue
import threading
import time
from collections.abc import Iterator

import serial

from core.errors import InputError
from drivers.base import TRIGGERS, register
from drivers.trigger import protocol as proto
from drivers.trigger.errors import (
    TriggerCommandError,
    TriggerDisconnectedError,
    TriggerPortError,
    TriggerProtocolError,
    TriggerResetError,
    TriggerTimeoutError,
)
from drivers.trigger.events import TriggerEvent

ERROR_MEANINGS = {
    "UNKNOWN": "unknown command (firmware too old?)",
    "ARG": "bad argument",
    "RANGE": "argument out of range",
    "BUSY": "not allowed while running",
    "CHECKSUM": "line corrupted",
    "LONG": "line too long",
}


@register(TRIGGERS, "serial")
class SerialTriggerBox:
    """A trigger box on a serial port (a path such as /dev/ttyACM0, or a pyserial URL)."""

    name = "serial"

    def __init__(
        self,
        port: str,
        *,
        baud: int = proto.BAUD,
        cycle: int = 2,
        source: str = "auto",
        pulse_us: int = 100,
        timeout_s: float = 0.5,
        retries: int = 2,
        boot_wait_s: float = 2.5,
        max_events: int = 4096,
    ) -> None:
        if not proto.CYC_MIN <= int(cycle) <= proto.CYC_MAX:
            raise InputError(f"trigger box {port}: cycle {cycle} out of range {proto.CYC_MIN}-{proto.CYC_MAX}")
        if str(source).upper() not in proto.SOURCES:
            raise InputError(f"trigger box {port}: source {source!r} must be one of int, ext, auto")
        if not proto.PW_MIN_US <= int(pulse_us) <= proto.PW_MAX_US:
            lo, hi = proto.PW_MIN_US, proto.PW_MAX_US
            raise InputError(f"trigger box {port}: pulse_us {pulse_us} out of range {lo}-{hi}")
        self.port = str(port)
        self.baud = int(baud)
        self.cycle = int(cycle)
        self.source = str(source).upper()
        self.pulse_us = int(pulse_us)
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.boot_wait_s = float(boot_wait_s)
        self.version = ""
        self.boot_id: int | None = None
        self.active_source = "-"
        self.rate_hz = 0.0
        self.missed_events = 0  # event lines lost (gaps in the count); the triggers still fired
        self.garbage_bytes = 0  # bytes on the line that were not valid protocol lines
        self._ser: serial.Serial | None = None
        self._reader: threading.Thread | None = None
        self._stop_reader = threading.Event()
        self._replies: queue.Queue[tuple[str, ...]] = queue.Queue()
        self._events: collections.deque[TriggerEvent] = collections.deque(maxlen=max_events)
        self._cond = threading.Condition()
        self._cmd_lock = threading.RLock()
        self._running = False
        self._last_count = 0
        self._fault: Exception | None = None  # raised at the next call (reset, phase error, unplug)
        self._disconnected: str | None = None
        self._open()

    # -- Trigger protocol -------------------------------------------------------------------
    def start(self, rate_hz: float) -> None:
        """(Re)configure and start firing; the counter restarts at 0. Clears a reported reset."""
        mhz = round(float(rate_hz) * 1000)
        if not proto.RATE_MIN_MHZ <= mhz <= proto.RATE_MAX_MHZ:
            raise InputError(f"trigger box {self.port}: rate {rate_hz} Hz out of range 1-250 Hz")
        with self._cmd_lock:
            self._ensure_link()
            with self._cond:
                self._fault = None
            self.command("STOP")
            self.command("CYC", self.cycle)
            self.command("SRC", self.source)
            self.command("PW", self.pulse_us)
            self.command("RATE", proto.format_rate(mhz))
            self.active_source = self.command("START")[0]  # the reader sets _running at the OK, in line order
            self.rate_hz = mhz / 1000.0

    def stop(self) -> None:
        with self._cmd_lock:
            self._ensure_link()
            self._running = False
            self.command("STOP")
            self.active_source = "-"

    def counter(self) -> int:
        """Triggers fired since start(), asked from the box (raises TriggerResetError after a reset)."""
        with self._cmd_lock:
            self._raise_fault()
            self._ensure_link()
            count = self._int(self.command("CNT"), 0, "CNT")
            self._raise_fault()  # the reader compared it with the events before it on the line
            return count

    def close(self) -> None:
        with self._cmd_lock:
            if self._ser is not None and self._running and self._disconnected is None:
                with contextlib.suppress(Exception):
                    self.command("STOP", retries=0)
            self._running = False
            self._close_port()

    # -- events -----------------------------------------------------------------------------
    def next_event(self, timeout_s: float = 1.0) -> TriggerEvent:
        """The oldest unread trigger event; raises on reset, unplug, bad phase, or silence."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                self._raise_fault()
                if self._events:
                    return self._events.popleft()
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._cond.wait(left)
        self._diagnose_silence(timeout_s)
        raise AssertionError("unreachable")  # _diagnose_silence always raises

    def events(self, timeout_s: float = 1.0) -> Iterator[TriggerEvent]:
        while True:
            yield self.next_event(timeout_s)

    def drain_events(self) -> list[TriggerEvent]:
        """Everything received so far, without waiting (may raise a pending fault)."""
        with self._cond:
            self._raise_fault()
            out = list(self._events)
            self._events.clear()
            return out

    @property
    def last_count(self) -> int:
        """The newest count seen in an event line, without asking the box (no I/O, no latency).

        As fresh as `counter()` (an event line lags its trigger by ~4 ms; a CNT round trip takes
        ~6 ms at 38400 baud), but it relies on event lines: use `counter()` to confirm.
        """
        with self._cond:
            return self._last_count

    def peek_counter(self) -> int:
        """`last_count`, but raising a reset or fault the reader has seen, like `counter()` — with no I/O.

        The capture loop polls this every millisecond: a CNT round trip per poll would need more
        than the 38400-baud line carries (about 300 queries/s, 4.9 kB/s against 3.8 kB/s).
        """
        self._raise_fault()
        return self.last_count

    # -- other box commands -----------------------------------------------------------------
    def status(self) -> dict[str, object]:
        with self._cmd_lock:
            self._ensure_link()
            f = self.command("STAT")
            if len(f) != 8:
                raise TriggerProtocolError(f"trigger box {self.port}: malformed STAT reply {f!r}")
            st = {
                "running": f[0] == "1",
                "source": f[1],
                "active": f[2],
                "rate_hz": (proto.parse_rate(f[3]) or 0) / 1000.0,
                "cycle": self._int(f, 4, "STAT"),
                "pulse_us": self._int(f, 5, "STAT"),
                "count": self._int(f, 6, "STAT"),
                "boot_id": self._int(f, 7, "STAT"),
            }
            if st["boot_id"] != self.boot_id:
                self._flag_reset(f"boot id changed from {self.boot_id} to {st['boot_id']}")
                self.boot_id = st["boot_id"]  # type: ignore[assignment]
            elif self._running and not st["running"]:
                self._flag_reset("it is stopped although it was started")
            return st

    def reset_box(self) -> None:
        """Reboot the box (watchdog); waits for it to answer again."""
        with self._cmd_lock:
            self.command("RESET")
            self._running = False
            self._handshake(self.boot_wait_s)
            with self._cond:
                self._fault = None

    def reconnect(self, wait_s: float = 3.0) -> None:
        """Close and reopen the port (e.g. after an unplug), waiting up to wait_s for it to reappear."""
        with self._cmd_lock:
            self._close_port()
            deadline = time.monotonic() + wait_s
            while True:
                try:
                    self._open()
                    return
                except TriggerPortError:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.05)

    def __enter__(self) -> SerialTriggerBox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- port -------------------------------------------------------------------------------
    def _open(self) -> None:
        is_url = "://" in self.port
        if not is_url and not os.path.exists(self.port):
            raise TriggerPortError(
                f"trigger box: serial port {self.port} does not exist; check the USB cable and `slscan devices`"
            )
        try:
            ser = serial.serial_for_url(self.port, do_not_open=True, baudrate=self.baud, timeout=0.05)
            ser.write_timeout = self.timeout_s
            if not is_url:
                ser.exclusive = True
            ser.open()
        except (serial.SerialException, OSError, ValueError) as exc:
            code = getattr(exc, "errno", None)
            if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK):
                why = "is busy: close the other program using it"
            elif code in (errno.EACCES, errno.EPERM):
                why = "permission denied: add the user to the dialout group"
            else:
                why = f"cannot be opened ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
            raise TriggerPortError(f"trigger box: serial port {self.port} {why}") from None
        with contextlib.suppress(serial.SerialException, OSError):
            ser.reset_input_buffer()  # bytes from a previous session are not ours
        self._ser = ser
        self._disconnected = None
        self._replies = queue.Queue()
        with self._cond:
            self._events.clear()
            self._fault = None
        self._running = False
        self._last_count = 0
        self._stop_reader.clear()
        self._reader = threading.Thread(target=self._read_loop, args=(ser,), name="trigger-reader", daemon=True)
        self._reader.start()
        try:
            self._handshake(self.boot_wait_s)
        except Exception:
            self._close_port()
            raise

    def _close_port(self) -> None:
        self._stop_reader.set()
        if self._reader is not None:
            self._reader.join(1.0)
            self._reader = None
        if self._ser is not None:
            with contextlib.suppress(Exception):
                self._ser.close()
            self._ser = None

    def _ensure_link(self) -> None:
        if self._disconnected is not None:
            self.reconnect()

    def _handshake(self, wait_s: float) -> None:
        """VER until the box answers (an Uno reboots when the port opens): check product, note boot id."""
        garbage0 = self.garbage_bytes
        deadline = time.monotonic() + wait_s
        reply: tuple[str, ...] | None = None
        while reply is None:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            try:
                reply = self.command("VER", retries=0, timeout_s=min(self.timeout_s, left))
            except TriggerTimeoutError:
                continue
            except TriggerProtocolError:
                continue
        if reply is None:
            if self._disconnected is not None:
                raise TriggerDisconnectedError(f"trigger box {self.port}: {self._disconnected}")
            if self.garbage_bytes > garbage0:
                raise TriggerProtocolError(
                    f"trigger box {self.port} answers garbage ({self.garbage_bytes - garbage0} bytes, no valid line in "
                    f"{wait_s:g} s): check the baud rate ({self.baud}) and that this port is the trigger box"
                )
            raise TriggerTimeoutError(
                f"trigger box {self.port} does not answer (no reply to VER in {wait_s:g} s): check it is powered, "
                "flashed with the slscan firmware, and that this port is the trigger box"
            )
        if len(reply) < 3 or reply[0] != proto.PRODUCT:
            raise TriggerProtocolError(
                f"trigger box {self.port}: the device is not an {proto.PRODUCT} box (VER -> {','.join(reply)})"
            )
        self.version = reply[1]
        self.boot_id = self._int(reply, 2, "VER")
        with self._cond:  # a BOOT line before this reply is the box starting up, not a reset mid-session
            if isinstance(self._fault, TriggerResetError):
                self._fault = None

    # -- commands ---------------------------------------------------------------------------
    def command(
        self, name: str, *args: object, retries: int | None = None, timeout_s: float | None = None
    ) -> tuple[str, ...]:
        """Send one protocol command, return the reply's fields after `OK,NAME` (ERR -> TriggerCommandError).

        Every command is idempotent, so a timed-out or corrupted one is simply sent again.
        """
        line = proto.encode(name, *args)
        timeout = self.timeout_s if timeout_s is None else timeout_s
        garbage0 = self.garbage_bytes
        for _attempt in range(1 + (self.retries if retries is None else retries)):
            while not self._replies.empty():  # a late reply to an earlier, timed-out command
                self._replies.get_nowait()
            self._write(line)
            deadline = time.monotonic() + timeout
            while True:
                left = deadline - time.monotonic()
                if left <= 0 or self._disconnected is not None:
                    break
                try:
                    fields = self._replies.get(timeout=min(left, 0.05))
                except queue.Empty:
                    continue
                kind, cmd = fields[0], fields[1] if len(fields) > 1 else ""
                if kind == "ERR" and cmd == "?":
                    break  # our line arrived corrupted: send it again
                if cmd != name:
                    continue
                if kind == "OK":
                    return fields[2:]
                code = fields[2] if len(fields) > 2 else "?"
                shown = ",".join([name, *map(str, args)])
                raise TriggerCommandError(
                    f"trigger box {self.port} refused {shown}: {code} ({ERROR_MEANINGS.get(code, 'unknown error')})",
                    code,
                )
        if self._disconnected is not None:
            raise TriggerDisconnectedError(f"trigger box {self.port}: {self._disconnected}; reconnect the cable")
        if self.garbage_bytes > garbage0:
            raise TriggerProtocolError(
                f"trigger box {self.port} answered {name} with garbage: check the baud rate ({self.baud}) and the cable"
            )
        raise TriggerTimeoutError(
            f"trigger box {self.port} did not answer {name} within {timeout:g} s: check it is powered and connected"
        )

    def _write(self, data: bytes) -> None:
        ser = self._ser
        if ser is None:
            raise TriggerPortError(f"trigger box {self.port} is closed")
        try:
            ser.write(data)
        except serial.SerialTimeoutException:
            raise TriggerTimeoutError(
                f"trigger box {self.port}: write blocked for {self.timeout_s:g} s; check the cable"
            ) from None
        except (serial.SerialException, OSError) as exc:
            self._disconnected = f"write failed ({exc})"
            raise TriggerDisconnectedError(
                f"trigger box {self.port}: the port went away ({exc}); check the cable"
            ) from None

    def _int(self, fields: tuple[str, ...], i: int, what: str) -> int:
        try:
            return int(fields[i])
        except (IndexError, ValueError):
            raise TriggerProtocolError(f"trigger box {self.port}: malformed {what} reply {fields!r}") from None

    # -- reader thread ----------------------------------------------------------------------
    def _read_loop(self, ser: serial.Serial) -> None:
        decoder = proto.LineDecoder()
        while not self._stop_reader.is_set():
            try:
                data = ser.read(max(1, ser.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                if self._stop_reader.is_set():
                    return
                self._disconnected = f"the port went away ({str(exc).splitlines()[0] if str(exc) else exc!r})"
                with self._cond:
                    if self._running:
                        self._fault = TriggerDisconnectedError(
                            f"trigger box {self.port}: {self._disconnected}; check the cable, then start again"
                        )
                    self._cond.notify_all()
                return
            if not data:
                continue
            now = time.monotonic_ns()
            before = decoder.discarded
            for item in decoder.feed(data):
                if isinstance(item, proto.BadLine):
                    self.garbage_bytes += len(item.raw)
                else:
                    self._on_line(item.fields, now)
            self.garbage_bytes += decoder.discarded - before

    def _on_line(self, fields: tuple[str, ...], now_ns: int) -> None:
        kind = fields[0]
        if kind == "T":
            self._on_event(fields, now_ns)
        elif kind == "BOOT":
            with contextlib.suppress(IndexError, ValueError):
                self.boot_id = int(fields[3])
            cause = fields[4] if len(fields) > 4 else "?"
            self._flag_reset(f"it rebooted (cause {cause})")
        elif kind in ("OK", "ERR"):
            cmd = fields[1] if len(fields) > 1 else ""
            if kind == "OK" and cmd in ("START", "STOP"):
                with self._cond:  # lines before this reply belong to the previous run
                    self._events.clear()
                    self._last_count = 0
                    self.missed_events = 0
                    self._running = cmd == "START"
            elif kind == "OK" and cmd == "CNT" and len(fields) > 2 and fields[2].isdigit():
                # compared here, in line order: events read later must not count against it
                if self._running and int(fields[2]) < self._last_count:
                    self._flag_reset(f"its count went back from {self._last_count} to {fields[2]}")
            self._replies.put(fields)
        else:
            self.garbage_bytes += 1

    def _on_event(self, fields: tuple[str, ...], now_ns: int) -> None:
        try:
            count, phase = int(fields[1]), int(fields[2])
        except (IndexError, ValueError):
            self.garbage_bytes += 1
            return
        with self._cond:
            if not self._running:
                return  # a run this driver did not start (e.g. left running by a previous session)
            if count <= self._last_count:
                self._flag_reset(f"its count went back from {self._last_count} to {count}")
            elif phase != (count - 1) % self.cycle:
                self._fault = TriggerProtocolError(
                    f"trigger box {self.port}: event {count} has phase {phase}, expected {(count - 1) % self.cycle} "
                    f"for a {self.cycle}-pattern cycle; the frame/pattern pairing cannot be trusted"
                )
            else:
                self.missed_events += count - self._last_count - 1
                self._last_count = count
                self._events.append(TriggerEvent(count, phase, now_ns))
            self._cond.notify_all()

    def _flag_reset(self, why: str) -> None:
        with self._cond:
            was_running = self._running
            self._running = False
            self._fault = TriggerResetError(
                f"trigger box {self.port} reset: {why}{', frames since then are lost' if was_running else ''}; "
                "check its power supply and cable, then start again"
            )
            self._cond.notify_all()

    def _raise_fault(self) -> None:
        with self._cond:
            fault = self._fault
            if fault is not None and not isinstance(fault, TriggerProtocolError):
                self._fault = None
            if fault is not None:
                raise fault

    def _diagnose_silence(self, timeout_s: float) -> None:
        """No event in timeout_s: find out why (reset? stopped? vsync gone? box dead?) and raise that."""
        with self._cmd_lock:
            if self._disconnected is not None:
                raise TriggerDisconnectedError(f"trigger box {self.port}: {self._disconnected}; check the cable")
            st = self.status()  # raises TriggerTimeoutError if the box stopped answering
            self._raise_fault()  # a reset found by status()
            if not st["running"]:
                raise TriggerTimeoutError(f"trigger box {self.port}: no trigger events, the box is not started")
            if st["active"] == "EXT":
                raise TriggerTimeoutError(
                    f"trigger box {self.port}: no trigger in {timeout_s:g} s from the projector vsync; "
                    "check the vsync cable (pin D2) or use source int"
                )
            raise TriggerTimeoutError(
                f"trigger box {self.port}: no trigger event line in {timeout_s:g} s although running at "
                f"{st['rate_hz']} Hz; check the cable"
            )
