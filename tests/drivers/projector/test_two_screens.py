"""The projector on the second monitor of a two-monitor X server (Xorg dummy driver, RandR outputs)."""

from __future__ import annotations

import numpy as np
import pytest

from core.patterns import make_patterns
from drivers.projector import ProjectorSetupError, PygletProjector, list_screens, window

pytestmark = pytest.mark.xserver

PROJ = (800, 600)  # DUMMY1, right of the 1024x768 DUMMY0


@pytest.fixture
def grabber(two_screen_grabber):
    return two_screen_grabber


def test_list_screens_in_pyglet_order(two_screen_xserver):
    assert list_screens(two_screen_xserver) == [
        {"index": 0, "name": "DUMMY0", "x": 0, "y": 0, "width": 1024, "height": 768},
        {"index": 1, "name": "DUMMY1", "x": 1024, "y": 0, "width": 800, "height": 600},
    ]


@pytest.mark.parametrize("screen", [1, "DUMMY1"])
def test_pattern_lands_exactly_on_screen_1(two_screen_xserver, grabber, screen):
    ps = make_patterns("two-shot", PROJ)
    with PygletProjector(screen, PROJ, display=two_screen_xserver) as p:
        assert (p.screen_index, p.screen_name, p.size) == (1, "DUMMY1", PROJ)
        p.load(ps.images)
        for i in (1, 0):
            p.show(i)
            np.testing.assert_array_equal(grabber.grab(1024, 0, *PROJ), ps.images[i])
            assert not grabber.grab(0, 0, 1024, 768).any(), "the first monitor must stay untouched"
        p.show(None)
        assert not grabber.grab(1024, 0, *PROJ).any()


def test_size_of_the_other_monitor_is_refused(two_screen_xserver):
    with pytest.raises(ProjectorSetupError, match=r"screen 1 \(DUMMY1\) .* is 800x600, not the projector's 1024x768"):
        PygletProjector(1, (1024, 768), display=two_screen_xserver)


def test_window_that_lands_on_the_wrong_screen_is_refused(two_screen_xserver, monkeypatch):
    """What pyglet does on systems that ignore `screen=`: the window opens on the first monitor."""
    from pyglet.window.xlib import XlibWindow

    monkeypatch.setattr(XlibWindow, "get_location", lambda self: (0, 0))
    monkeypatch.setattr(window, "SETTLE_S", 0.1)  # no window manager will fix it: do not wait 1 s
    with pytest.raises(ProjectorSetupError, match=r"opened at \+0\+0, not on the screen at \+1024\+0.*refusing"):
        PygletProjector(1, PROJ, display=two_screen_xserver)


def test_hidpi_framebuffer_mismatch_is_refused(two_screen_xserver, monkeypatch):
    """A 2x desktop scale: the framebuffer is twice the screen's pixels; nothing would be 1:1."""
    from pyglet.window.xlib import XlibWindow

    monkeypatch.setattr(XlibWindow, "get_framebuffer_size", lambda self: (2 * self._width, 2 * self._height))
    monkeypatch.setattr(window, "SETTLE_S", 0.1)
    with pytest.raises(ProjectorSetupError, match=r"framebuffer is 1600x1200, not 800x600 .*HiDPI"):
        PygletProjector(1, PROJ, display=two_screen_xserver)
