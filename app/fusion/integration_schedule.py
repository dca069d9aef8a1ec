"""When the live fusion thread integrates a tracked scan: always when no newer scan waits, else on a grid of due
times `period` apart, so that integration keeps its rate while tracking takes every moment there is.

Due times on a grid, not `period` after the last integration: an integration waits for the next tracked scan, a
fraction of a tracking step past its due time, and counting the period from there would lose that fraction every
time (at 0.08 s and ~25 ms a step, 9.7 integrations a second instead of 12.5). One period late or more, the grid
starts again from now: no burst of integrations to catch up; and so it does after an integration made before its
due time (no newer scan waited), which would otherwise push the grid a period further each time.
"""

from __future__ import annotations


class IntegrationSchedule:
    def __init__(self, period_s: float) -> None:
        self.period_s = float(period_s)
        self._due: float | None = None  # the next integration's due time (None: none done yet)

    def wants(self, now: float, newer_waiting: bool) -> bool:
        """Integrate the scan just tracked at `now`? (newer_waiting: a newer scan is already in the mailbox)"""
        return not newer_waiting or self._due is None or now >= self._due

    def integrated(self, now: float) -> None:
        """An integration was done at `now`."""
        on_grid = self._due is not None and 0.0 <= now - self._due < self.period_s
        self._due = self._due + self.period_s if on_grid else now + self.period_s
