"""`slscan live` with no display runs the session headless (the README's first command on a bare machine)."""

from __future__ import annotations

import os

from core.imageio import read_float_tiff


def test_live_without_display_runs_headless_and_saves_the_last_scan(run_cli, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    r = run_cli("live", "--frames", "40", "--out", tmp_path / "scan", env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "running --headless" in r.stderr and "Traceback" not in r.stderr
    assert "depth maps out" in r.stdout
    depth = read_float_tiff(next((tmp_path / "scan").glob("depth*.tiff")))
    assert depth.shape == (480, 640) and (depth > 0).mean() > 0.3  # the face preset fills most of the view
