"""The wizard's operator window on a real X server (Xvfb), driven by scripted keys in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from calibration.model import Calibration

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
    w.handle_key(k.ENTER)                  # verdict + validation scan
    w.handle_key(k.S)
    w.win.dispatch_events()
    w.on_draw()
    w.win.flip()
    print("LABEL", w.label.text.replace("\\n", " | "))
    print("POSES", len(w.state.poses))
    w.close()
    """
)


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
