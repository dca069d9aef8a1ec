"""Wall-clock times in slscan's files: ISO 8601 UTC with milliseconds (2026-12-02T06:40:00.123Z)."""

from __future__ import annotations

import datetime
import time

from core.errors import InputError


def now_ns() -> int:
    """The host's wall clock, ns since the epoch."""
    return time.time_ns()


def monotonic_to_wall_ns(monotonic_ns: int) -> int:
    """A time.monotonic_ns() reading as the wall clock (ns since the epoch), by the two clocks' offset now."""
    return time.time_ns() - (time.monotonic_ns() - int(monotonic_ns))


def wall_clock_iso(wall_ns: int) -> str:
    """ISO 8601 UTC with milliseconds, e.g. 2026-12-02T06:40:00.123Z."""
    t = datetime.datetime.fromtimestamp(wall_ns / 1e9, tz=datetime.UTC)
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


def parse_wall_clock(text: object, where: str) -> int:
    """The ns since the epoch of a wall_clock_iso string (or the datetime YAML makes of one left unquoted); InputError
    naming `where` otherwise."""
    if isinstance(text, datetime.datetime):
        t = text if text.tzinfo is not None else text.replace(tzinfo=datetime.UTC)
        return int(t.timestamp() * 1e9)
    if not isinstance(text, str) or not text.endswith("Z"):
        raise InputError(f"{where} must be an ISO 8601 UTC time like 2026-12-02T06:40:00.123Z, found {text!r}")
    try:
        t = datetime.datetime.fromisoformat(text[:-1]).replace(tzinfo=datetime.UTC)
    except ValueError:
        raise InputError(
            f"{where} must be an ISO 8601 UTC time like 2026-12-02T06:40:00.123Z, found {text!r}"
        ) from None
    return int(t.timestamp() * 1e9)
