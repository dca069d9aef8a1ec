"""The screens of the X display, in pyglet's order (the order `--screen N` and the projector use).

pyglet is imported here lazily, only when a display is actually opened, so the rest of slscan
runs on machines without a display. Screen order comes from pyglet (XRandR outputs, else
Xinerama, else the one X screen) and can differ from the desktop's own numbering: choose by
name when in doubt (`slscan devices` lists both).
"""

from __future__ import annotations

import os
from typing import Any

from core.errors import DeviceError

# One X connection per display name: pyglet never closes a display connection, so reuse it.
_displays: dict[str, Any] = {}


class NoDisplayError(DeviceError):
    """There is no X display to open a window on."""


class ScreenNotFoundError(DeviceError):
    """The requested screen (index or name) does not exist on the display."""


def import_pyglet() -> Any:
    """Import pyglet for an X window: no shadow window (one less context), never headless."""
    import pyglet

    pyglet.options["shadow_window"] = False
    return pyglet


def display_name(display: str | None = None) -> str:
    """The X display to use: the argument, else $DISPLAY; a clear error if there is none."""
    name = display if display is not None else os.environ.get("DISPLAY", "")
    if not name:
        raise NoDisplayError("no X display: DISPLAY is not set (run on a desktop, or start an X server, e.g. Xvfb)")
    return name


def open_display(display: str | None = None) -> Any:
    """The pyglet display for `display` (default $DISPLAY), connecting once per name."""
    name = display_name(display)
    if name in _displays:
        return _displays[name]
    import_pyglet()
    try:
        import pyglet.display
    except ImportError as exc:  # no libX11 / libGL on this machine
        raise NoDisplayError(f"cannot load the X11/OpenGL libraries pyglet needs ({exc})") from None
    try:
        disp = pyglet.display.Display(name=name)
    except Exception as exc:
        # pyglet has two NoSuchDisplayException classes (display.xlib and window): match by name.
        if type(exc).__name__ != "NoSuchDisplayException":
            raise
        raise NoDisplayError(f"cannot connect to X display {name!r}: is the X server running?") from None
    _displays[name] = disp
    return disp


def _describe(index: int, screen: Any) -> dict:
    return {
        "index": index,
        "name": str(screen.get_monitor_name()),
        "x": int(screen.x),
        "y": int(screen.y),
        "width": int(screen.width),
        "height": int(screen.height),
    }


def list_screens(display: str | None = None) -> list[dict]:
    """Every screen as {index, name, x, y, width, height}, in the order `--screen N` counts.

    Raises NoDisplayError (a DeviceError, one clear line) when there is no display to ask.
    """
    disp = open_display(display)
    return [_describe(i, s) for i, s in enumerate(disp.get_screens())]


def find_screen(spec: int | str, display: str | None = None) -> tuple[int, Any]:
    """(index, pyglet screen) for a screen index (0, "1") or a screen name ("HDMI-1")."""
    disp = open_display(display)
    screens = disp.get_screens()
    listing = ", ".join(f"{i}: {s.get_monitor_name()} {s.width}x{s.height}+{s.x}+{s.y}" for i, s in enumerate(screens))
    text = str(spec).strip()
    if isinstance(spec, int) or text.lstrip("-").isdigit():
        index = int(text)
        if 0 <= index < len(screens):
            return index, screens[index]
        raise ScreenNotFoundError(f"screen {index} does not exist on display {display_name(display)!r} ({listing})")
    names = [str(s.get_monitor_name()) for s in screens]
    for wanted in (text, text.lower()):
        for i, name in enumerate(names):
            if (name if wanted is text else name.lower()) == wanted:
                return i, screens[i]
    raise ScreenNotFoundError(f"no screen named {text!r} on display {display_name(display)!r} ({listing})")
