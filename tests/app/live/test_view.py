"""The operator window on a real X server (Xvfb): it shows results, and its keys work —
space writes a snapshot, r starts and stops a recording, m switches scheme, q quits."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from core.dump import read_dump
from core.imageio import read_float_tiff, read_rgb

pytestmark = pytest.mark.xserver

SCRIPT = textwrap.dedent(
    """
    import argparse, time
    import numpy as np
    from Xlib import X, display as xdisplay
    from app.session import build_session
    from app.pointview import _TURBO
    from app.view import LiveView
    from drivers.projector.screens import import_pyglet

    pyglet = import_pyglet()
    from pyglet.window import key

    session = build_session(None, sim_overrides={"camera_size": [320, 240]})
    view = LiveView(session, argparse.Namespace(timeout=3.0, workers=1, frames=None, png_level=0))
    # what the window says while a switched-to scheme's decoder is compiled or loaded (Session.processor)
    Session = type(session)
    processor = Session.processor
    def processor_spy(self):
        print("status while preparing:", view.status_text, flush=True)
        return processor(self)
    Session.processor = processor_spy
    plan = [("result", None), ("wait", 0.3), ("points", None), ("press", key.LEFT), ("wait", 0.3), ("points", None),
            ("wait", 0.3), ("points", None),
            ("press", key.SPACE), ("wait", 0.8), ("wait", 0.05), ("press", key.R), ("wait", 0.6), ("press", key.R),
            ("press", key.M), ("wait", 1.0), ("press", key.Q)]
    state = {"i": 0, "until": 0.0}
    palette = {tuple(c) for c in _TURBO} | {(0, 0, 0)}

    def panel_pixels():
        # What the X server shows in the 3D panel (below its title), read back from the root window.
        x0, y0 = view.win.get_location()
        x, y, w, h = view.panel_rects[3]
        conn = xdisplay.Display()
        raw = conn.screen().root.get_image(x0 + x, y0 + y + 22, w, h - 22, X.ZPixmap, 0xFFFFFFFF).data
        conn.close()
        return np.frombuffer(raw, np.uint8).reshape(h - 22, w, 4)[:, :, 2::-1]

    def drive(dt):
        if state["i"] >= len(plan) or time.monotonic() < state["until"]:
            return
        what, arg = plan[state["i"]]
        if what == "result":
            if view.pipe.latest is None:
                return
        elif what == "press":
            view.win.dispatch_event("on_key_press", arg, 0)
        elif what == "wait":
            state["until"] = time.monotonic() + arg
        elif what == "points":
            px = panel_pixels()
            lit = px.any(axis=2)
            colours = {tuple(c) for c in px.reshape(-1, 3)}
            print("points", f"{lit.mean():.3f}", len(colours - palette), "yaw", view.points.pose().yaw_deg, flush=True)
        print("step", what, view.message, flush=True)
        state["i"] += 1

    pyglet.clock.schedule_interval(drive, 0.05)
    code = view.run()
    print("points_ms", np.median(view.points_ms), "redraw_ms", np.median(view.redraw_ms), flush=True)
    raise SystemExit(code)
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
    assert "status while preparing: [two-shot] switching to one-shot: preparing its decoder" in r.stdout
    # the 3D panel shows depth-coloured points (the depth panel's palette, nothing else), orbiting,
    # then turned by the left arrow key
    points = [line.split() for line in r.stdout.splitlines() if line.startswith("points ")]
    assert len(points) == 3, r.stdout
    for _, lit, foreign, _, _ in points:
        assert 0.1 < float(lit) < 0.95 and int(foreign) == 0, points
    yaws = [float(p[4]) for p in points]
    assert yaws[1] == yaws[2] != yaws[0], yaws  # the arrow key stopped the orbit and turned the view
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
