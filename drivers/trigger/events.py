"""What a trigger reports per fired pulse; the capture loop pairs camera frames with these."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TriggerEvent:
    count: int  # 1, 2, ... since start(); gaps mean event lines were lost, not triggers
    phase: int  # position in the pattern cycle: (count - 1) % cycle; 0 = a cycle starts
    host_timestamp_ns: int  # time.monotonic_ns() when the line arrived (trigger time + ~4 ms)
