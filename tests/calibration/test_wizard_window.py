"""The wizard's operator window on a real X server (Xvfb), driven by scripted keys in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from core.calibration import Calibration

# both scripts end alike: Enter (verdict + validation scan), S (save), one drawn frame, then the label and pose
# count the tests read
FINISH = """
w.handle_key(k.ENTER)
w.handle_key(k.S)
w.win.dispatch_events()
w.on_draw()
w.win.flip()
print("LABEL", w.label.text.replace("\\n", " | "))
print("POSES", len(w.state.poses))
w.close()
"""

SCRIPT = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from calibration.wizard import SimBoardSource, WizardWindow
    from calibration.solve import MIN_POSES

    tmp = Path(sys.argv[1])
    src = SimBoardSource("checkerboard", seed=1, supersample=2)
    w = WizardWindow(src, tmp / "cal.yaml", tmp / "cal.capture")
    k = w.key
    w.handle_key(k.S)                      # nothing solved yet: not saved
    print("EARLY", w.verdict[-1])
    w.handle_key(k.SPACE)                  # fronto-parallel start pose: kept, no error yet
    for _ in range(MIN_POSES):
        w.handle_key(k.N)
        w.handle_key(k.SPACE)
    w.handle_key(k.U)                      # undo the last pose
    w.handle_key(k.N)
    w.handle_key(k.SPACE)
    w.handle_key(k.C)                      # colour levels at the last (near, bright) pose
    print("NEAR", " | ".join(w.verdict))
    w.verdict.clear()
    w.handle_key(k.F)                      # board flat, mid-range: measure again
    w.handle_key(k.C)
    print("COLOUR", " | ".join(w.verdict))
    """
)
SCRIPT += FINISH


@pytest.mark.slow
@pytest.mark.xserver
def test_wizard_window_guides_to_a_saved_calibration(tmp_path, xserver):
    env = {**os.environ, "DISPLAY": xserver}
    run = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(tmp_path)], capture_output=True, text=True, env=env, timeout=600
    )
    assert run.returncode == 0, run.stderr[-2000:]
    out = run.stdout
    assert "EARLY not saved" in out
    label = next(line for line in out.splitlines() if line.startswith("LABEL"))
    assert "board seen (70 corners)" in label
    assert "verdict: good" in label and "validation scan of the flat board" in label and "wrote" in label
    assert "POSES 6" in out
    colour = next(line for line in out.splitlines() if line.startswith("COLOUR"))
    assert "colour response: gamma R 2.1" in colour or "colour response: gamma R 2.2" in colour
    assert "warning" not in colour
    near = next(line for line in out.splitlines() if line.startswith("NEAR"))
    assert "warning: channel R is nearly saturated" in near  # the near pose's white clips: said
    cal = Calibration.load(tmp_path / "cal.yaml")
    assert cal.rms["camera_rms"] < 0.2
    assert cal.color_mixing is not None and abs(cal.color_mixing[0, 1] - 0.0909) < 0.01
    assert cal.extra["camera_gamma"] == 1.8 and (tmp_path / "cal.capture" / "response" / "levels.yaml").is_file()
    # the capture the wizard saved is a capture `--from` reads: undo removed the undone pose
    poses = sorted(p.name for p in (tmp_path / "cal.capture").iterdir() if p.name.startswith("pose_"))
    assert poses == [f"pose_{i:03d}" for i in range(6)]


def test_wizard_without_a_display_is_one_line(run_cli, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    proc = run_cli("calibrate", "--out", tmp_path / "c.yaml", env=env)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "DISPLAY" in proc.stderr


RIG_SCRIPT = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from app.config import load_config
    from calibration.auto import fronto_pose, rig_board
    from calibration.poses import plan_poses
    from calibration.rig_source import RigBoardSource, open_devices
    from calibration.wizard import WizardWindow
    from drivers.projector.window import PygletProjector
    from drivers.sim.devices import shared_bench

    class Tee:
        # the pyglet projector window and the sim projector (what the simulated camera sees), in step
        thread_bound = True

        def __init__(self, sim, window):
            self.sim, self.window, self.size = sim, window, window.size
            self.name = f"{window.name}+{sim.name}"
        def load(self, images):
            self.sim.load(images)
            self.window.load(images)
        def show(self, index):
            self.sim.show(index)
            return self.window.show(index)
        def poll(self):
            return self.window.poll()
        def request_stop(self):
            self.window.request_stop()
        @property
        def stop_requested(self):
            return self.window.stop_requested
        def close(self):
            self.sim.close()
            self.window.close()

    tmp = Path(sys.argv[1])
    cfg = load_config(tmp / "rig.yaml")
    bench = shared_bench(scene="checkerboard", seed=7, supersample=2)
    rig = bench.rig
    cam, proj, trig = open_devices(cfg)
    window = PygletProjector(screen=0, size=(1024, 768))  # fullscreen on the Xvfb screen
    src = RigBoardSource(cfg, rig_board(rig), devices=(cam, Tee(proj, window), trig))
    w = WizardWindow(src, tmp / "cal.yaml", tmp / "cal.capture")
    k = w.key
    src.preview.wait()
    w.poll()
    print("LIVE", w.label.text.splitlines()[0])
    for rvec, tvec in plan_poses(src.board, rig.calibration, 6, seed=3):
        rig.set_board_pose(rvec, tvec)  # the operator's hand
        w.handle_key(k.N)                  # no keyboard moves on a rig: ignored
        w.handle_key(k.SPACE)
    print("MESSAGES", " | ".join(w.state.messages))
    shown = [i for i, _ in window.flips]
    n = len(src.patterns)
    runs = [j for j in range(len(shown) - n + 1) if shown[j : j + n] == list(range(n))]
    print("WINDOW", len(runs), shown[-1])
    rig.set_board_pose(*fronto_pose(src.board, rig))
    """
)
RIG_SCRIPT += FINISH + "src.close()\n"


@pytest.mark.slow
@pytest.mark.xserver
def test_wizard_window_on_a_rig_with_a_projector_window(tmp_path, xserver):
    """The rig path: sim camera and trigger from the registries, a real pyglet projector window."""
    (tmp_path / "rig.yaml").write_text(
        "rig:\n"
        "  camera: &sim {driver: sim, scene: checkerboard, seed: 7, supersample: 2}\n"
        "  projector: *sim\n"
        "  trigger: *sim\n"
        "capture:\n"
        "  rate_hz: 20\n"
    )
    env = {**os.environ, "DISPLAY": xserver}
    run = subprocess.run(
        [sys.executable, "-c", RIG_SCRIPT, str(tmp_path)], capture_output=True, text=True, env=env, timeout=600
    )
    assert run.returncode == 0, run.stderr[-2000:]
    out = run.stdout
    assert "LIVE board seen (70 corners)" in out, out
    assert "POSES 6" in out, out
    window = next(line for line in out.splitlines() if line.startswith("WINDOW")).split()
    assert int(window[1]) >= 6 and window[2] == "0"  # every pattern shown in order; white again for the live view
    label = next(line for line in out.splitlines() if line.startswith("LABEL"))
    assert "verdict: good" in label and "validation scan of the board" in label and "wrote" in label
    assert "n next pose" not in label  # the board moves by hand on a rig
    cal = Calibration.load(tmp_path / "cal.yaml")
    assert cal.projector_size == (1024, 768) and cal.rms["camera_rms"] < 0.2 and "camera_gamma" not in cal.extra
    poses = sorted(p.name for p in (tmp_path / "cal.capture").iterdir() if p.name.startswith("pose_"))
    assert poses == [f"pose_{i:03d}" for i in range(6)]
