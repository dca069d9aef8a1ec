"""X servers for the projector tests: the session's Xvfb (`xserver`, tests/conftest.py) and a
two-monitor Xorg (dummy driver), both started by `start_x_server` (tests/conftest.py).
Pixels are read back from the X server (python-xlib GetImage on the root window), not from
OpenGL: what the server shows is what a projector would get.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator

import numpy as np
import pytest

XVFB_SIZE = (1024, 768)  # the size of the session's Xvfb (tests/conftest.py)


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


# Two monitors on one X screen: Xorg's dummy driver with RandR outputs DUMMY0 (1024x768 at +0+0)
# and DUMMY1 (800x600 at +1024+0), as a desktop with a projector on the right would look.
DUMMY_CONF = """\
Section "Device"
    Identifier "dummy"
    Driver "dummy"
    VideoRam 64000
EndSection
Section "Monitor"
    Identifier "monitor"
    HorizSync 5.0-1000.0
    VertRefresh 5.0-200.0
    Modeline "1024x768" 63.50 1024 1072 1176 1328 768 771 775 798
    Modeline "800x600" 38.25 800 832 912 1024 600 603 607 624
EndSection
Section "Screen"
    Identifier "screen"
    Device "dummy"
    Monitor "monitor"
    DefaultDepth 24
    SubSection "Display"
        Depth 24
        Modes "1024x768"
        Virtual 1824 768
    EndSubSection
EndSection
"""
DUMMY_DRIVER = "/usr/lib/xorg/modules/drivers/dummy_drv.so"


@pytest.fixture(scope="session")
def two_screen_xserver(tmp_path_factory: pytest.TempPathFactory, start_x_server) -> str:
    """The display name of an Xorg (dummy driver) with two monitors side by side."""
    if shutil.which("Xorg") is None or not os.path.exists(DUMMY_DRIVER) or shutil.which("xrandr") is None:
        pytest.skip("Xorg with the dummy driver is not installed (.ci/run: xserver-xorg-video-dummy)")
    folder = tmp_path_factory.mktemp("xorg-dummy")
    (folder / "xorg.conf").write_text(DUMMY_CONF)
    argv = ["Xorg", "-config", str(folder / "xorg.conf"), "-logfile", str(folder / "xorg.log")]
    name = start_x_server([*argv, "-noreset", "-nolisten", "tcp", "-nocursor"])
    env = {**os.environ, "DISPLAY": name}
    for cmd in (
        ["xrandr", "--addmode", "DUMMY1", "800x600"],
        ["xrandr", "--output", "DUMMY1", "--mode", "800x600", "--right-of", "DUMMY0"],
    ):
        subprocess.run(cmd, env=env, check=True, capture_output=True, timeout=20)
    return name


@pytest.fixture(scope="session")
def two_screen_grabber(two_screen_xserver: str) -> Iterator[ScreenGrabber]:
    grabber = ScreenGrabber(two_screen_xserver)
    yield grabber
    grabber.close()
