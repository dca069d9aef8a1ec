"""IntegrationSchedule: with scans always queued, integrations keep their rate whatever a tracking step takes."""

from __future__ import annotations

import pytest

from app.fusion.integration_schedule import IntegrationSchedule


def _integrations_per_s(track_s: float, integrate_s: float, period_s: float = 0.08, seconds: float = 60.0) -> float:
    """A fusion thread on a simulated clock: a newer scan always waits; each scan is tracked, then integrated when
    the schedule wants it."""
    schedule = IntegrationSchedule(period_s)
    now, done = 0.0, 0
    while now < seconds:
        now += track_s
        if schedule.wants(now, newer_waiting=True):
            now += integrate_s
            schedule.integrated(now)
            done += 1
    return done / seconds


@pytest.mark.parametrize("track_s", [0.005, 0.021, 0.026, 0.05])
def test_queued_scans_are_integrated_at_the_period_s_rate(track_s):
    # one per period: 12.5 a second at 0.08 s, not one per (period + the wait for the next tracked scan)
    assert _integrations_per_s(track_s, integrate_s=0.012) == pytest.approx(12.5, abs=0.2)


def test_a_thread_slower_than_the_period_integrates_every_scan_without_bursts():
    # tracking + integration 0.15 s a scan: every scan integrated, one per scan (no catch-up of missed due times)
    assert _integrations_per_s(0.138, integrate_s=0.012) == pytest.approx(1 / 0.15, abs=0.05)


def test_without_a_newer_scan_every_scan_is_integrated():
    schedule = IntegrationSchedule(0.08)
    schedule.integrated(1.0)
    assert schedule.wants(1.001, newer_waiting=False) and not schedule.wants(1.001, newer_waiting=True)
    assert schedule.wants(1.08, newer_waiting=True)


def test_a_long_stall_restarts_the_grid_from_now():
    schedule = IntegrationSchedule(0.08)
    schedule.integrated(1.0)
    schedule.integrated(5.0)  # 4 s later (a stall): the next is due a period on, not at once
    assert not schedule.wants(5.01, newer_waiting=True) and schedule.wants(5.08, newer_waiting=True)


def test_integrations_before_their_due_time_do_not_push_the_grid_ahead():
    # scans arriving slowly (none waiting) are each integrated; the first queued scan a period after the last one
    # is integrated again
    schedule = IntegrationSchedule(0.08)
    for k in range(21):
        schedule.integrated(1.0 + 0.01 * k)
    assert not schedule.wants(1.25, newer_waiting=True) and schedule.wants(1.28, newer_waiting=True)
