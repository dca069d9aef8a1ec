"""The operator window on a real X server (Xvfb): it shows results, and its keys work —
space writes a snapshot, r starts and stops a recording, m switches scheme, q quits."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from app.dump import read_dump
from app.imageio import read_float_tiff, read_rgb

pytestmark = pytest.mark.xserver

SCRIPT = textwrap.dedent(
    """
    import argparse, time
    from app.commands.live import build_session
    from app.view import LiveView
    from drivers.projector.screens import import_pyglet

    pyglet = import_pyglet()
    from pyglet.window import key

    session = build_session(None, sim_overrides={"camera_size": [320, 240]})
    view = LiveView(session, argparse.Namespace(timeout=3.0, workers=1, frames=None, png_level=0))
    plan = [("result", None), ("press", key.SPACE), ("press", key.R), ("wait", 0.6), ("press", key.R),
            ("press", key.M), ("wait", 1.0), ("press", key.Q)]
    state = {"i": 0, "until": 0.0}

    def drive(dt):
        if state["i"] >= len(plan):
            return
        what, arg = plan[state["i"]]
        win = next(iter(pyglet.app.windows), None)
        if win is None or time.monotonic() < state["until"]:
            return
        if what == "result":
            if view.pipe.latest is None:
                return
        elif what == "press":
            win.dispatch_event("on_key_press", arg, 0)
        elif what == "wait":
            state["until"] = time.monotonic() + arg
        print("step", what, view.message, flush=True)
        state["i"] += 1

    pyglet.clock.schedule_interval(drive, 0.05)
    raise SystemExit(view.run())
    """
)


def test_view_shows_results_and_its_keys_work(tmp_path, xserver):
    env = {**os.environ, "DISPLAY": xserver}
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=280
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "snapshot written to snapshot-000" in r.stdout
    assert "scheme: one-shot" in r.stdout
    snap = tmp_path / "snapshot-000"
    depth = read_float_tiff(snap / "depth.tiff")
    assert depth.shape == (240, 320) and (depth > 0).mean() > 0.1
    assert read_rgb(snap / "stripes.png").shape == (240, 320, 3)
    assert (snap / "cloud.ply").read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")
    recs = sorted(tmp_path.glob("rec-*"))
    assert len(recs) == 1
    dump = read_dump(recs[0])
    assert len(dump.frames) >= 5 and dump.scheme == "two-shot"
    assert f"recorded {len(dump.frames)} frames to {recs[0].name}" in r.stdout
    assert np.all(np.diff([f.frame_id for f in dump.frames]) >= 1)
