"""The live session with a real projector window and the operator view in one process (Xvfb).

The rig: the pyglet projector window (fullscreen, 1024x768) shows the patterns that the virtual
rig's camera watches (sim camera and trigger, config `projector: {driver: pyglet}`). Both windows
live on the main thread; the capture loop's projector calls are served there between redraws.
Checked: what the X server shows is exactly the pattern the pipeline's flip log says was shown
at that flip, the view window is open beside it, and the session stops cleanly on q in the view
and when the projector window is closed (a WM_DELETE_WINDOW message, what a window manager sends).

With the trigger box: the Python emulator of the box on a real pty, opened by the serial driver,
paces the loop; the projector's vsync is wired to the box (source ext) and to the virtual
camera's trigger (each edge steps the rig's clock and fires the box together, as
tests/reliability/test_faults.py's VsyncBridge does), so the camera's frames carry the box's count.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.xserver

RIG = """\
rig:
  camera: {driver: sim}
  projector: {driver: pyglet, screen: 0}
  trigger: {driver: sim}
sim:
  scene: face
  camera_size: [320, 240]
  projector_size: [1024, 768]
scheme: {name: two-shot}
capture: {rate_hz: 60}
"""

SCRIPT = textwrap.dedent(
    """
    import argparse, sys
    import numpy as np
    from Xlib import X, display as xdisplay
    from Xlib.protocol import event
    from app.session import build_session
    from app.view import LiveView
    from drivers.projector.screens import import_pyglet

    pyglet = import_pyglet()
    from pyglet.window import key

    how = sys.argv[2]
    session = build_session(sys.argv[1])
    if how == "trigger-box":
        import dataclasses, threading
        from drivers.trigger.emulator import TriggerBoxEmulator
        from drivers.trigger.serial_box import SerialTriggerBox

        emu = TriggerBoxEmulator()
        sim_devices = session.make_devices

        def vsync_wire(sim_trigger, stop):
            bench = sim_trigger.bench
            sim_trigger.start(60)  # the rig's stepped clock: ticks only come from the vsync edges
            while not stop.wait(1 / 60):
                with emu._lock:
                    if emu.running and emu.active == "EXT":
                        sim_trigger.step()
                        emu.vsync()

        def make_devices():
            cam, proj, sim_trigger = sim_devices()
            stop = threading.Event()
            threading.Thread(target=vsync_wire, args=(sim_trigger, stop), daemon=True).start()
            box = SerialTriggerBox(emu.port, cycle=2, source="ext", timeout_s=1.0)
            close = box.close
            box.close = lambda: (stop.set(), close())
            return cam, proj, box

        session = dataclasses.replace(session, make_devices=make_devices)
    view = LiveView(session, argparse.Namespace(timeout=3.0, workers=1, frames=None, png_level=0))
    conn = xdisplay.Display()
    root = conn.screen().root
    state = {"grabs": [], "stopping": False}

    def windows():
        return {w.get_wm_name(): w for w in root.query_tree().children if w.get_wm_name()}

    def drive(dt):
        pipe = view.pipe
        if pipe is None or pipe.latest is None or pipe.loop is None or state["stopping"]:
            return
        grabs = state["grabs"]
        both = len({p for p, _, _ in grabs}) == 2
        if len(grabs) < 8 or (not both and len(grabs) < 40):
            # On the main thread no flip can happen during the grab: the screen holds the window's last flip.
            pattern, flip_ns = view.projector.projector.window.flips[-1]  # proxy -> WatchedWindow -> window
            if grabs and grabs[-1][1] == flip_ns:
                return  # one grab per flip
            raw = root.get_image(0, 0, 1024, 768, X.ZPixmap, 0xFFFFFFFF).data
            px = np.frombuffer(raw, np.uint8).reshape(768, 1024, 4)[:, :, 2::-1]
            grabs.append((pattern, flip_ns, px))
            return
        # The pipeline logs a flip once its show returned: match each grab to its log entry by flip time.
        log = {s.flip_ns: s for s in pipe.loop.flips.entries()}
        for _, flip_ns, px in grabs:
            shown = log.get(flip_ns)
            tag = None if shown is None else shown.pattern
            exact = tag is not None and np.array_equal(px, session.patterns.images[tag])
            print("grab", tag, exact, None if shown is None else shown.late, flush=True)
        wins = windows()
        for name in ("slscan live", "slscan projector"):
            w = wins.get(name)
            viewable = w is not None and w.get_attributes().map_state == X.IsViewable
            g = w.get_geometry() if w is not None else None
            print("window", name.replace(" ", "_"), viewable, g and f"{g.width}x{g.height}", flush=True)
        state["stopping"] = True
        if how == "view-q":
            view.win.dispatch_event("on_key_press", key.Q, 0)
        else:  # the operator closes the projector window
            w = wins["slscan projector"]
            proto, delete = conn.intern_atom("WM_PROTOCOLS"), conn.intern_atom("WM_DELETE_WINDOW")
            w.send_event(event.ClientMessage(window=w, client_type=proto, data=(32, [delete, X.CurrentTime, 0, 0, 0])))
            conn.flush()

    pyglet.clock.schedule_interval(drive, 0.05)
    code = view.run()
    conn.sync()
    print("projector window left", "slscan projector" in windows(), flush=True)
    print("frames", view.pipe.capture.frames, "depth maps", view.pipe.stats.decoded, flush=True)
    print("trigger", type(view.pipe.loop.trigger).__name__, view.pipe.capture.refused, flush=True)
    raise SystemExit(code)
    """
)


@pytest.mark.parametrize("how", ["view-q", "close-projector", "trigger-box"])
def test_projector_window_and_view_in_one_process(tmp_path, xserver, how):
    (tmp_path / "rig.yaml").write_text(
        RIG.replace("scene: face", "scene: face\n  stepped: true") if how == "trigger-box" else RIG
    )
    env = {**os.environ, "DISPLAY": xserver}
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(tmp_path / "rig.yaml"), how],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert r.returncode == 0, r.stdout + r.stderr[-3000:]
    lines = r.stdout.splitlines()
    grabs = [line.split() for line in lines if line.startswith("grab ")]
    assert 8 <= len(grabs) <= 40, r.stdout
    # every grab: the screen is exactly the pattern the pipeline tagged that flip with; both patterns seen
    assert all(g[2] == "True" for g in grabs), r.stdout
    assert {g[1] for g in grabs} == {"0", "1"}, r.stdout
    assert "window slscan_live True 640x542" in lines, r.stdout  # 2 x 2 panels of 320x240 + three status lines
    assert "window slscan_projector True 1024x768" in lines, r.stdout
    assert "projector window left False" in lines, r.stdout
    frames = next(line.split() for line in lines if line.startswith("frames "))
    assert int(frames[1]) > 20 and int(frames[4]) >= 1
    if how == "close-projector":
        assert "slscan live: stopped cleanly: the projector window was closed" in r.stdout
    trigger = next(line.split() for line in lines if line.startswith("trigger "))
    assert trigger[1] == ("SerialTriggerBox" if how == "trigger-box" else "SimTrigger"), trigger
    assert "Traceback" not in r.stderr


def test_window_size_not_the_virtual_projectors_is_one_line(run_cli, tmp_path, xserver):
    (tmp_path / "rig.yaml").write_text(RIG.replace("projector_size: [1024, 768]", "projector_size: [800, 600]"))
    r = run_cli("live", "--config", tmp_path / "rig.yaml", env={**os.environ, "DISPLAY": xserver}, cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().splitlines() == [
        f"slscan live: error: projector pyglet:0 is 1024x768 but {tmp_path / 'rig.yaml'} key 'sim.projector_size' "
        "says 800x600"
    ]


def test_virtual_camera_with_another_trigger_is_refused(run_cli, tmp_path):
    (tmp_path / "rig.yaml").write_text(
        RIG.replace("trigger: {driver: sim}", "trigger: {driver: serial, port: /dev/null}")
    )
    r = run_cli("live", "--headless", "--config", tmp_path / "rig.yaml", cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "key 'rig': the virtual rig's camera and trigger go together" in r.stderr
