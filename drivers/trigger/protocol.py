"""Trigger-box line protocol (PROTOCOL.md): framing, checksum, and a resyncing line decoder.

Pure byte handling, shared by the driver and the emulator; no I/O here.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

BAUD = 38400
PRODUCT = "SLTRIG"
MAX_BODY = 60
RATE_MIN_MHZ = 1_000
RATE_MAX_MHZ = 250_000
CYC_MIN, CYC_MAX = 1, 16
PW_MIN_US, PW_MAX_US = 8, 1000
SOURCES = ("INT", "EXT", "AUTO")
ERROR_CODES = ("UNKNOWN", "ARG", "RANGE", "BUSY", "CHECKSUM", "LONG")


def checksum(body: bytes) -> int:
    """XOR of every byte of the body (between '$' and '*')."""
    x = 0
    for b in body:
        x ^= b
    return x


def encode(*fields: object) -> bytes:
    """`encode("RATE", "60.000")` -> b"$RATE,60.000*HH\\n"."""
    body = ",".join(str(f) for f in fields).encode("ascii")
    if len(body) > MAX_BODY or any(b < 0x20 or b > 0x7E or b in b"$*" for b in body):
        raise ValueError(f"not a valid protocol line body: {body!r}")
    return b"$" + body + b"*%02X\n" % checksum(body)


def format_rate(mhz: int) -> str:
    return f"{mhz // 1000}.{mhz % 1000:03d}"


def parse_rate(text: str) -> int | None:
    """'59.94' -> 59940 (milli-hertz); None if not a plain decimal with at most 3 decimals."""
    whole, dot, frac = text.partition(".")
    if not whole.isdigit() or not whole.isascii() or len(whole) > 6 or (dot and (not frac.isdigit() or len(frac) > 3)):
        return None
    return int(whole) * 1000 + int((frac + "000")[:3])


@dataclass(frozen=True)
class Line:
    """One decoded line: its fields, and whether it carried a checksum."""

    fields: tuple[str, ...]
    raw: bytes
    had_checksum: bool = True

    @property
    def name(self) -> str:
        return self.fields[0] if self.fields else ""


@dataclass(frozen=True)
class BadLine:
    """A line that started with '$' but is unusable: reason is 'CHECKSUM' or 'LONG'."""

    reason: str
    raw: bytes


class LineDecoder:
    """Feed bytes in any chunking; get Line / BadLine out. Resyncs on '$'.

    Bytes outside a line, and lines containing non-printable bytes, are dropped and counted in
    `discarded` (how much garbage was seen: the driver uses it to tell "garbage" from "silence").
    """

    def __init__(self, require_checksum: bool = True) -> None:
        self.require_checksum = require_checksum
        self._buf: bytearray | None = None
        self._long = False
        self.discarded = 0

    def feed(self, data: bytes) -> Iterator[Line | BadLine]:
        for b in data:
            if b == 0x24:  # '$': a new line, whatever came before
                if self._buf is not None:
                    self.discarded += len(self._buf) + 1
                self._buf, self._long = bytearray(), False
            elif self._buf is None:
                self.discarded += 1
            elif b == 0x0A:
                buf, self._buf = self._buf, None
                out = self._finish(bytes(buf))
                if out is not None:
                    yield out
            elif b == 0x0D:
                continue
            elif b < 0x20 or b > 0x7E:
                self.discarded += len(self._buf) + 2
                self._buf = None
            elif len(self._buf) >= MAX_BODY + 3:
                self._long = True
            else:
                self._buf.append(b)

    def _finish(self, line: bytes) -> Line | BadLine | None:
        raw = b"$" + line + b"\n"
        if self._long:
            return BadLine("LONG", raw)
        body, star, hh = line.rpartition(b"*")
        if not star:
            if self.require_checksum:
                self.discarded += len(raw)
                return None
            body, had = line, False
        else:
            try:
                ok = len(hh) == 2 and int(hh, 16) == checksum(body)
            except ValueError:
                ok = False
            if not ok or b"*" in body:
                return BadLine("CHECKSUM", raw)
            had = True
        if len(body) > MAX_BODY:
            return BadLine("LONG", raw)
        return Line(tuple(body.decode("ascii").split(",")), raw, had)
