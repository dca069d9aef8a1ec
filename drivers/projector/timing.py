"""Statistics of recorded flip times: the interval the projector really achieved and its jitter."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FlipStats:
    flips: int
    mean_ms: float  # mean interval between consecutive flips
    jitter_ms: float  # standard deviation of the intervals
    min_ms: float
    max_ms: float
    late: int  # intervals longer than 1.5 target periods (a refresh was missed)

    def summary(self) -> str:
        if self.flips < 2:
            return f"{self.flips} flip(s): too few to measure an interval"
        return (
            f"{self.flips} flips, interval {self.mean_ms:.3f} ms mean ({1000 / self.mean_ms:.2f} Hz), "
            f"jitter {self.jitter_ms:.3f} ms std, min {self.min_ms:.3f} ms, max {self.max_ms:.3f} ms, {self.late} late"
        )


def flip_stats(times_ns: Sequence[int], target_hz: float | None = None) -> FlipStats:
    """Interval statistics of monotonic flip times (ns). `late` needs target_hz (else 0)."""
    t = np.asarray(times_ns, dtype=np.int64)
    if t.size < 2:
        return FlipStats(int(t.size), float("nan"), float("nan"), float("nan"), float("nan"), 0)
    d = np.diff(t) / 1e6
    late = int(np.count_nonzero(d > 1.5 * 1000.0 / target_hz)) if target_hz else 0
    return FlipStats(int(t.size), float(d.mean()), float(d.std()), float(d.min()), float(d.max()), late)
