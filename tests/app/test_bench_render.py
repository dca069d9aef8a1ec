"""`slscan bench --render`: the still rows keep their keys; the moving rows time frames that move."""

from __future__ import annotations

import argparse

from app.bench import render

KEYS = {"scene", "resolution", "precompute_s", "median_ms", "p95_ms", "unprepared_median_ms", "frames_per_s"}


def test_render_rows_still_and_moving(monkeypatch) -> None:
    monkeypatch.setattr(render, "SIZES", ((160, 120),))
    monkeypatch.setattr(render, "MOVING_SIZE", (160, 120))
    rows = render.run(argparse.Namespace(render_scene="plane", render_frames=5))
    motions = ["still", "lateral 8 mm/frame", "turntable 2 deg/frame", "still (nothing moves)"]
    assert [r["motion"] for r in rows] == motions  # the plane has nothing that moves
    assert [r["scene"] for r in rows] == ["plane", "cube", "turntable", "plane"]
    for r in rows:
        assert KEYS <= set(r) and r["resolution"] == "160x120" and r["median_ms"] > 0
    table = render.format_table(rows).splitlines()
    assert len(table) == len(rows) + 2 and "turntable 2 deg/frame" in table[3]
