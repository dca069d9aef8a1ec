"""`slscan project`, screen listing and the no-display paths, on a real Xvfb."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest

from drivers.projector import NoDisplayError, list_screens

STATS = re.compile(r"screen 0: (\d+) flips, interval ([\d.]+) ms mean .*jitter ([\d.]+) ms std")


def _env(display: str | None) -> dict:
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    if display is not None:
        env["DISPLAY"] = display
    return env


@pytest.mark.xserver
def test_list_screens_on_xvfb(display):
    assert list_screens() == [{"index": 0, "name": "screen", "x": 0, "y": 0, "width": 1024, "height": 768}]


def test_no_display_is_a_typed_error(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.raises(NoDisplayError, match="DISPLAY is not set"):
        list_screens()
    with pytest.raises(NoDisplayError, match=r"cannot connect to X display ':4711'"):
        list_screens(":4711")


def test_pyglet_is_imported_only_when_a_window_opens():
    code = (
        "import sys; import app.cli, drivers.projector, drivers.base as b; app.cli.build_parser(); "
        "assert 'pyglet' in b.PROJECTORS; print(sorted(m for m in sys.modules if m.startswith('pyglet')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=_env(None))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


@pytest.mark.xserver
def test_project_alternates_and_prints_interval_and_jitter(run_cli, xserver):
    r = run_cli("project", "--scheme", "two-shot", "--screen", "0", "--hz", "60", "--seconds", "1", env=_env(xserver))
    assert r.returncode == 0, r.stderr
    assert "projecting 2 two-shot pattern(s) 1024x768 on screen 0 (screen) at 60 Hz" in r.stdout
    m = STATS.search(r.stdout)
    assert m, r.stdout
    flips, mean_ms, jitter_ms = int(m[1]), float(m[2]), float(m[3])
    assert 10 <= flips <= 61 and 16.0 <= mean_ms <= 100.0 and jitter_ms < mean_ms  # sane, not a speed test


@pytest.mark.xserver
@pytest.mark.parametrize(
    "args, message",
    [
        (["--screen", "2"], r"screen 2 does not exist on display ':\d+' \(0: screen 1024x768\+0\+0\)"),
        (["--screen", "DP-7"], "no screen named 'DP-7'"),
        (["--size", "1920x1080"], "screen 0 .*is 1024x768, not the projector's 1920x1080"),
        (["--hz", "-5"], r"argument --hz: '-5' must be 0 or more"),
    ],
)
def test_project_bad_input_is_one_line_exit_2(run_cli, xserver, args, message):
    r = run_cli("project", "--scheme", "two-shot", "--seconds", "1", *args, env=_env(xserver))
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert re.search(r"^slscan project: error: " + message, r.stderr), r.stderr


def test_project_without_display_is_one_line_exit_2(run_cli):
    r = run_cli("project", "--scheme", "two-shot", env=_env(None))
    assert r.returncode == 2
    assert r.stderr.strip() == (
        "slscan project: error: no X display: DISPLAY is not set (run on a desktop, or start an X server, e.g. Xvfb)"
    )


def _start_project(start, xserver: str) -> subprocess.Popen:
    proc = start(
        "project",
        "--scheme",
        "graycode",
        "--hz",
        "30",
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(xserver),
    )
    first = proc.stdout.readline()
    assert first.startswith("projecting 42 graycode pattern(s)"), first + proc.stderr.read()
    time.sleep(0.3)  # a few flips
    return proc


def _press(xserver: str, keysym_name: str) -> None:
    from Xlib import XK, X
    from Xlib import display as xdisplay
    from Xlib.ext import xtest

    conn = xdisplay.Display(xserver)
    try:
        code = conn.keysym_to_keycode(XK.string_to_keysym(keysym_name))
        xtest.fake_input(conn, X.KeyPress, code)
        xtest.fake_input(conn, X.KeyRelease, code)
        conn.sync()
    finally:
        conn.close()


@pytest.mark.xserver
@pytest.mark.parametrize("stop", ["Escape", "q", "SIGINT"])
def test_project_stops_cleanly_on_esc_q_and_ctrl_c(xserver, slscan_process, stop):
    proc = _start_project(slscan_process, xserver)
    if stop == "SIGINT":
        proc.send_signal(signal.SIGINT)
    else:
        _press(xserver, stop)
    out, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err
    assert err == ""
    assert re.search(r"screen 0: \d+ flips, interval [\d.]+ ms mean", out), out
