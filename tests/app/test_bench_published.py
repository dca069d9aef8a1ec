"""`slscan bench --live`'s "published" row: a receiver process gets the live session's stream (no timing asserted:
the figures belong to docs/performance.md)."""

from __future__ import annotations

import pytest

from app.bench import live

pytest.importorskip("zmq")
pytestmark = pytest.mark.xdist_group("live-stream")


def test_the_published_row_counts_what_the_receiver_process_got():
    row = live._published_row(frames=90, workers=1)  # 640x480 (the bench's size), 1.5 s at 60 Hz
    assert row["run"].startswith("published") and row["frames"] == 90
    made = int(row["error"].split(" of ")[1].split()[0])
    assert made >= 10 and row["lost"] == 0, row  # (how many a busy machine makes is not this test's concern)
    assert "0 sequence gap(s)" in row["error"] and "the end message did not arrive" not in row["error"]
    assert 0 < row["latency_p50_ms"] < 1000  # milliseconds, measured in the receiver process
