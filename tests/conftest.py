"""Shared test helpers. Each area keeps its own fixtures in its own tests/<area>/conftest.py.

The one X server: `xserver` is a session-wide Xvfb (1024x768, depth 24) for every test that opens a
window (projector, operator view, calibration wizard). `start_x_server` starts another server (the
two-monitor Xorg of the projector tests) the same way. Fixtures, not imports: the suite runs with
--import-mode=importlib.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator

import pytest

XVFB_SIZE = (1024, 768)  # the projector tests' fullscreen window is this size


def _start_x_server(argv: list[str]) -> tuple[subprocess.Popen, str]:
    """Start an X server with `-displayfd`; returns it and its display name once it accepts clients.

    The server picks a free display number itself, so parallel sessions never collide.
    """
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        [argv[0], "-displayfd", str(write_fd), *argv[1:]],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    os.close(write_fd)
    number = b""
    deadline = time.monotonic() + 20
    with os.fdopen(read_fd, "rb") as pipe:
        # The server writes "N\n" once it accepts connections, or closes the pipe if it dies.
        while not number.endswith(b"\n") and time.monotonic() < deadline:
            chunk = pipe.read(1)
            if not chunk:
                break
            number += chunk
    if not number.strip().isdigit():
        proc.kill()
        err = proc.communicate(timeout=5)[1].decode(errors="replace")
        raise RuntimeError(f"{argv[0]} did not start: {err.strip()[-500:]}")
    return proc, f":{int(number)}"


def _stop_x_server(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@pytest.fixture(scope="session")
def start_x_server() -> Iterator[Callable[[list[str]], str]]:
    """start(argv) -> display name of a new X server, stopped at the end of the session."""
    procs: list[subprocess.Popen] = []

    def start(argv: list[str]) -> str:
        proc, name = _start_x_server(argv)
        procs.append(proc)
        return name

    try:
        yield start
    finally:
        for proc in procs:
            _stop_x_server(proc)


@pytest.fixture(scope="session")
def xserver(start_x_server: Callable[[list[str]], str]) -> str:
    """The display name (":N") of the session's Xvfb, 1024x768 depth 24 (at 16 pixels are not exact)."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (.ci/run installs it: apt-get install xvfb)")
    w, h = XVFB_SIZE
    return start_x_server(["Xvfb", "-screen", "0", f"{w}x{h}x24", "-nolisten", "tcp", "-nocursor"])


@pytest.fixture
def run_cli():
    """Run `slscan ARGS...` in a subprocess; returns CompletedProcess (text, captured)."""

    def run(*args: str, timeout: float = 120, **kw) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True, timeout=timeout, **kw
        )

    return run
