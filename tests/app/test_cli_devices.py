"""`slscan devices` against real components: the viky.cti producer, a real Xvfb, the machine's ports."""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import pytest


def test_lists_viky_cameras_and_the_sim(run_cli):
    r = run_cli("devices", "--cti", "viky", "--json", env={**os.environ, "DISPLAY": ":nonexistent"})
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    specs = [c.get("spec") for c in out["cameras"]["items"]]
    assert "sim" in specs
    viky = [c for c in out["cameras"]["items"] if c.get("driver") == "genicam" and "error" not in c]
    assert len(viky) == 3, out["cameras"]
    assert all(c["spec"].startswith("genicam:") for c in viky)
    # no display: the screens section says so in one line instead of failing the command
    assert out["screens"]["items"] == [] and "\n" not in out["screens"]["error"]
    assert isinstance(out["serial_ports"]["items"], list)


def test_bad_producer_is_reported_in_its_section(run_cli, tmp_path):
    r = run_cli("devices", "--cti", tmp_path / "missing.cti", env={**os.environ, "DISPLAY": ":nonexistent"})
    assert r.returncode == 0 and "Traceback" not in r.stderr
    assert "missing.cti" in r.stdout and "sim" in r.stdout


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="Xvfb not installed (.ci/run installs it)")
def test_lists_the_screen_of_a_real_x_server(run_cli):
    xvfb = subprocess.Popen(
        ["Xvfb", "-displayfd", "1", "-screen", "0", "800x600x24", "-nolisten", "tcp"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )
    try:
        display = ":" + xvfb.stdout.readline().decode().strip()
        r = run_cli("devices", "--json", "--display", display)
        assert r.returncode == 0, r.stderr
        screens = json.loads(r.stdout)["screens"]["items"]
        assert [(s["width"], s["height"], s["x"], s["y"]) for s in screens] == [(800, 600, 0, 0)]
        text = run_cli("devices", "--display", display)
        assert "800x600 at +0+0" in text.stdout
    finally:
        xvfb.terminate()
        xvfb.wait(5)
