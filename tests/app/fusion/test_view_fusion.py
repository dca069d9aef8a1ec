"""Fusion in the operator window on a real X server (Xvfb) and the virtual rig's turntable: f starts fusion, the 3D
panel shows the model growing and the status line its state, s saves the mesh (read back here with trimesh, which
did not write it, against the rig's true surface), f stops it."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.xserver
trimesh = pytest.importorskip("trimesh")
pytest.importorskip("open3d")

CONFIG = Path(__file__).resolve().parents[3] / "config" / "sim_turntable.yaml"

SCRIPT = textwrap.dedent(
    """
    import argparse, sys, time
    import numpy as np
    from Xlib import X, display as xdisplay
    from app.session import build_session
    from app.pointview import _TURBO
    from app.view import LiveView
    from drivers.projector.screens import import_pyglet
    from drivers.sim import devices as simdev
    from drivers.sim.truth import surface_sample

    pyglet = import_pyglet()
    from pyglet.window import key

    # 0.25 deg a frame: small steps between the scans a loaded machine's fusion thread takes, and a tracking lag (the
    # decoder's errors stay with the camera on this nearly symmetric bust) too small to smear the nose into a ghost
    effects = {"render_ahead": True, "rotation_deg_per_frame": 0.25}
    session = build_session(sys.argv[1], sim_overrides={"camera_size": [320, 240], "effects": effects})
    rig = session.sim.rig
    steps = {}  # camera frame id -> the rig's motion step it was rendered at (its true object pose)
    render = simdev.SimCamera._render

    def spy(self, tick, pattern_tick):
        steps[tick] = self.bench.rig.frame_index
        return render(self, tick, pattern_tick)

    simdev.SimCamera._render = spy
    view = LiveView(session, argparse.Namespace(timeout=3.0, workers=1, frames=None, png_level=0, voxel_mm=1.0))
    palette = {tuple(c) for c in _TURBO} | {(0, 0, 0)}

    def fused():
        return 0 if view.fusion is None else view.fusion.fuser.stats.integrated

    mark = {}
    plan = [
        ("until", lambda: view.pipe.latest is not None), ("show", "before"), ("press", key.F),
        ("until", lambda: fused() >= 3), ("show", "early"), ("mark", None),
        ("until", lambda: fused() >= mark["n"] + 8), ("show", "later"),
        ("press", key.S), ("until", lambda: view.message.startswith(("model (", "save:"))), ("say", None),
        ("press", key.F),
        ("wait", 0.5), ("show", "stopped"), ("press", key.Q),
    ]
    state = {"i": 0, "until": 0.0, "deadline": time.monotonic() + 48}

    def panel_pixels():
        # what the X server shows in the 3D panel (below its title), read back from the root window
        x0, y0 = view.win.get_location()
        x, y, w, h = view.panel_rects[3]
        conn = xdisplay.Display()
        raw = conn.screen().root.get_image(x0 + x, y0 + y + 22, w, h - 22, X.ZPixmap, 0xFFFFFFFF).data
        conn.close()
        return np.frombuffer(raw, np.uint8).reshape(h - 22, w, 4)[:, :, 2::-1]

    def drive(dt):
        if time.monotonic() > state["deadline"]:
            print("timed out at step", state["i"], view.status_text, flush=True)
            view.quit = True
            return
        if state["i"] >= len(plan) or time.monotonic() < state["until"]:
            return
        what, arg = plan[state["i"]]
        if what == "until" and not arg():
            return
        if what == "press":
            view.win.dispatch_event("on_key_press", arg, 0)
        elif what == "wait":
            state["until"] = time.monotonic() + arg
        elif what == "say":
            print("said", view.message, flush=True)
        elif what == "mark":
            mark["n"] = fused()
        elif what == "show":
            state["show"] = arg
            state["until"] = time.monotonic() + 0.4  # the next redraws and status line are on screen
            plan.insert(state["i"] + 1, ("read", arg))
        elif what == "read":
            px = panel_pixels()
            np.save(f"panel-{arg}.npy", px)
            foreign = len({tuple(c) for c in px.reshape(-1, 3)} - palette)
            status = view.status_text.replace(chr(10), " / ")
            print("show", arg, f"{px.any(axis=2).mean():.4f}", foreign, "|", view.panel_titles[3].text, "|", status,
                  flush=True)
        state["i"] += 1

    pyglet.clock.schedule_interval(drive, 0.05)
    code = view.run()
    print("message", view.message, flush=True)
    if view.fusion is not None and view.fusion.fuser.poses:
        first = view.fusion.fuser.poses[0].frame_id  # the model's frame: the camera's at this frame
        truth = surface_sample(rig.moving_shapes)
        np.savez("truth.npz", P0=rig.object_pose(steps[first]), points=truth.points, normals=truth.normals)
    raise SystemExit(code)
    """
)


def _shown(stdout: str) -> dict[str, tuple[float, int, str, str]]:
    rows = {}
    for line in stdout.splitlines():
        if line.startswith("show "):
            head, title, status = line.split(" | ", 2)
            _, name, lit, foreign = head.split()
            rows[name] = (float(lit), int(foreign), title, status)
    return rows


def _count(status: str, what: str) -> int:
    # "fusion tracking: 12 fused, 0 dropped, ..." -> 12
    part = status.split("fusion ", 1)[1]
    return int(part.split(f" {what}")[0].rsplit(" ", 1)[-1])


def test_fusion_keys_show_the_model_growing_and_save_a_mesh_on_the_true_surface(tmp_path, xserver):
    env = {**os.environ, "DISPLAY": xserver}
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(CONFIG)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=58
    )
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "timed out" not in r.stdout, r.stdout
    shown = _shown(r.stdout)
    assert set(shown) == {"before", "early", "later", "stopped"}, r.stdout
    # before f: the scan's points and no fusion state; while fusing: the model's points, its state and counts
    assert shown["before"][2] == "3D points" and "fusion" not in shown["before"][3]
    for name in ("early", "later"):
        lit, foreign, title, status = shown[name]
        assert title.startswith("model (") and "fusion tracking:" in status, shown[name]
        assert 0.02 < lit < 0.95 and foreign == 0, shown[name]  # depth-coloured points, nothing else
    assert _count(shown["later"][3], "fused") >= _count(shown["early"][3], "fused") + 8
    points = [int(shown[n][2].split("(")[1].split()[0]) for n in ("early", "later")]
    assert points[1] > points[0], points  # the model grew as the bust turned
    before, early, later = (np.load(tmp_path / f"panel-{n}.npy").any(axis=2) for n in ("before", "early", "later"))
    assert (early != before).mean() > 0.01 and (later != early).mean() > 0.001
    # f again stopped fusion: the state says so and the panel is the scan's points again
    assert "fusion stopped:" in shown["stopped"][3] and shown["stopped"][2] == "3D points"
    # s wrote the mesh and the trajectory as `slscan fuse` does
    model = tmp_path / "model-000"
    assert f"written to {model.name}/model.ply, {model.name}/model.obj" in r.stdout, r.stdout
    rows = (model / "model.trajectory.csv").read_text().splitlines()
    assert rows[0].startswith("scan,frame_id,status,m00") and len(rows) >= 12
    mesh = trimesh.load(model / "model.ply", process=False)
    assert len(mesh.faces) > 1000
    assert len(trimesh.load(model / "model.obj", process=False).faces) == len(mesh.faces)
    # against the truth: the model's frame (the camera's at the first scan) into the object's
    t = np.load(tmp_path / "truth.npz")
    P0 = t["P0"]
    V = (np.asarray(mesh.vertices) - P0[:3, 3]) @ P0[:3, :3]
    from scipy.spatial import cKDTree

    _, i = cKDTree(t["points"]).query(V)
    err = np.abs(np.einsum("ij,ij->i", V - t["points"][i], t["normals"][i]))
    print("mesh vs truth: mean", err.mean(), "p90", np.percentile(err, 90), "vertices", len(V))
    # within half a voxel (1 mm) at the median, and a tail: the live thread tracks whatever scan is newest when it is
    # free, frames apart when the cores are busy, and the side the turn reveals last is the least accurate
    # (docs/performance.md, "Live fusion at 60 frames/s"). Seen: median 0.24-0.27 mm, p90 0.56-0.94 mm, alone and
    # beside one or two busy cores (at 0.5 deg a frame the lag smeared the nose: p90 up to 3.9 mm when loaded).
    # Accuracy targets are `slscan bench --fusion`'s.
    assert np.median(err) < 0.5 and np.percentile(err, 90) < 1.5, (np.median(err), np.percentile(err, 90))
