"""A real X server for the projector tests: Xvfb on a free display number, depth 24.

Xvfb picks the free display number itself (-displayfd) so parallel sessions never collide.
Pixels are read back from the X server (python-xlib GetImage on the root window), not from
OpenGL: what the server shows is what a projector would get.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections.abc import Iterator

import numpy as np
import pytest

XVFB_SIZE = (1024, 768)


def _start_xvfb(width: int, height: int) -> tuple[subprocess.Popen, str]:
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", f"{width}x{height}x24", "-nolisten", "tcp", "-nocursor"],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    os.close(write_fd)
    number = b""
    deadline = time.monotonic() + 20
    with os.fdopen(read_fd, "rb") as pipe:
        # Xvfb writes "N\n" once it accepts connections, or closes the pipe if it dies.
        while not number.endswith(b"\n") and time.monotonic() < deadline:
            chunk = pipe.read(1)
            if not chunk:
                break
            number += chunk
    if not number.strip().isdigit():
        proc.kill()
        err = proc.communicate(timeout=5)[1].decode(errors="replace")
        raise RuntimeError(f"Xvfb did not start: {err.strip()[-500:]}")
    return proc, f":{int(number)}"


@pytest.fixture(scope="session")
def xserver() -> Iterator[str]:
    """The display name (":N") of a session-wide Xvfb, stopped at the end of the session."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (.ci/run installs it: apt-get install xvfb)")
    proc, name = _start_xvfb(*XVFB_SIZE)
    try:
        yield name
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture
def display(xserver: str, monkeypatch: pytest.MonkeyPatch) -> str:
    """DISPLAY set to the session's Xvfb for this test."""
    monkeypatch.setenv("DISPLAY", xserver)
    return xserver


class ScreenGrabber:
    """Reads the X server's pixels back as RGB uint8 (H, W, 3)."""

    def __init__(self, name: str) -> None:
        from Xlib import X
        from Xlib import display as xdisplay

        self._X = X
        self.conn = xdisplay.Display(name)
        self.root = self.conn.screen().root

    def grab(self, x: int = 0, y: int = 0, width: int = XVFB_SIZE[0], height: int = XVFB_SIZE[1]) -> np.ndarray:
        raw = self.root.get_image(x, y, width, height, self._X.ZPixmap, 0xFFFFFFFF).data
        return np.frombuffer(raw, np.uint8).reshape(height, width, 4)[:, :, 2::-1].copy()  # BGRX -> RGB

    def close(self) -> None:
        self.conn.close()


@pytest.fixture(scope="session")
def screen_grabber(xserver: str) -> Iterator[ScreenGrabber]:
    grabber = ScreenGrabber(xserver)
    yield grabber
    grabber.close()
