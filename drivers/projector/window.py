"""The projector: a borderless fullscreen pyglet (OpenGL) window on one screen, pixel-exact.

How it draws: each pattern is uploaded once (`load`) into a texture attached to its own
framebuffer object, and `show(i)` copies it 1:1 into the window's back buffer with
glBlitFramebuffer (GL_NEAREST, same size: no filtering, no scaling), then flips. The upload
uses a negative pitch so numpy row 0 is the top row of the screen. Patterns pass through the
gamma/brightness table (`levels.py`, identity by default) before upload.

Safety at start-up: pyglet ignores `screen=` on some systems, HiDPI scaling makes the framebuffer
differ from the screen, and a projector may run another mode than expected. The window checks
that its framebuffer is exactly the projector size and sits exactly on the chosen screen, and
refuses to run (ProjectorSetupError) otherwise.

Threads and pacing: OpenGL and pyglet's window events belong to the thread that opened the
window. Every method except `request_stop` must be called from that thread; the capture loop
either runs the projector on its own thread (camera grabbing on another) or calls `show` itself:
  - `show(i)` / `present(i)` draws pattern i (None = black) and flips now; with vsync the flip
    lands on the next refresh. It pumps the window's events and returns the flip time
    (time.monotonic_ns, the clock Frame timestamps use when the device has none).
  - `run(order, hz, ...)` shows `order` cyclically, paced by absolute deadlines at `hz` (or by
    vsync alone with hz=None), until seconds/frames are done, Esc/q/close, or `request_stop()`
    from any thread; it returns the flip statistics of that run.
Every flip is logged as (pattern index or None, flip_time_ns) in `flips` (bounded).
"""

from __future__ import annotations

import ctypes
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from core.errors import DeviceError, InputError
from core.patterns import parse_size
from drivers.base import PROJECTORS, register
from drivers.projector.levels import apply_levels, levels_lut
from drivers.projector.screens import display_name, find_screen, import_pyglet
from drivers.projector.timing import FlipStats, flip_stats

QUIT_KEYS = ("ESCAPE", "Q")
SETTLE_S = 1.0  # how long a window manager may take to place the fullscreen window


class ProjectorSetupError(DeviceError):
    """The window cannot be exactly the projector: wrong screen, size, position or GL config."""


def _as_size(size: Sequence[int] | str | None) -> tuple[int, int] | None:
    if size is None:
        return None
    if isinstance(size, str):
        return parse_size(size)
    if len(size) != 2 or not all(isinstance(v, int | np.integer) and v > 0 for v in size):
        raise InputError(f"projector size {size!r} must be [width, height] in pixels")
    return int(size[0]), int(size[1])


@register(PROJECTORS, "pyglet")
class PygletProjector:
    """A fullscreen window on `screen` (index or name) of X display `display` (default $DISPLAY).

    size: the projector resolution (W, H) or "WxH"; None takes the screen's size. Either way the
    framebuffer must match it exactly. gamma, brightness: output levels (see levels.py).
    vsync: flip on the vertical retrace. finish: glFinish after each flip so the recorded flip
    time is when the swap completed, not when it was queued.
    """

    name: str
    size: tuple[int, int]
    thread_bound = True  # pyglet: every call but request_stop from the thread that opened the window

    def __init__(
        self,
        screen: int | str = 0,
        size: Sequence[int] | str | None = None,
        *,
        gamma: float = 1.0,
        brightness: float = 1.0,
        vsync: bool = True,
        finish: bool = True,
        display: str | None = None,
        log_length: int = 100_000,
    ) -> None:
        wanted = _as_size(size)
        self._lut = levels_lut(gamma, brightness)
        self.gamma, self.brightness = gamma, brightness
        self._finish = finish
        self._thread = threading.get_ident()
        self._stop = threading.Event()
        self._sources: list[np.ndarray] = []
        self._textures: list[Any] = []
        self._fbos: list[int] = []
        self._window: Any = None
        self.flips: deque[tuple[int | None, int]] = deque(maxlen=log_length)
        self.current: int | None = None

        self.screen_index, scr = find_screen(screen, display)
        self.screen_name = str(scr.get_monitor_name())
        where = f"screen {self.screen_index} ({self.screen_name}) of display {display_name(display)!r}"
        self.name = f"pyglet:{self.screen_index}"
        screen_size = (int(scr.width), int(scr.height))
        if wanted is not None and wanted != screen_size:
            raise ProjectorSetupError(
                f"{where} is {screen_size[0]}x{screen_size[1]}, not the projector's {wanted[0]}x{wanted[1]}: "
                "set the projector's native mode on that screen or fix the configured size"
            )
        self.size = screen_size
        self._open_window(scr, vsync, where)

    # ------------------------------------------------------------------ window

    def _open_window(self, scr: Any, vsync: bool, where: str) -> None:
        import_pyglet()
        import pyglet.window
        from pyglet import gl

        self._gl = gl
        self._keys = pyglet.window.key
        # 8 bits per channel: a default 16-bit config would quantise the patterns.
        config = gl.Config(double_buffer=True, red_size=8, green_size=8, blue_size=8)
        try:
            win = pyglet.window.Window(
                fullscreen=True,
                screen=scr,
                vsync=vsync,
                config=config,
                style=pyglet.window.Window.WINDOW_STYLE_BORDERLESS,
                caption="slscan projector",
            )
        except (pyglet.window.NoSuchConfigException, pyglet.gl.ContextException) as exc:
            raise ProjectorSetupError(f"{where}: no 8-bit-per-channel double-buffered OpenGL config ({exc})") from None
        self._window = win
        win.set_mouse_visible(False)
        win.push_handlers(on_key_press=self._on_key_press, on_close=self._on_close)
        # A window manager may place and resize a fullscreen window a little after it is mapped:
        # give it up to SETTLE_S before judging where the window is.
        deadline = time.monotonic() + SETTLE_S
        while True:
            win.dispatch_events()
            self._draw(None)
            win.flip()
            fb, loc = tuple(win.get_framebuffer_size()), tuple(win.get_location())
            if (fb == self.size and loc == (scr.x, scr.y)) or time.monotonic() > deadline:
                break
            time.sleep(0.02)
        problem = None
        if fb != self.size:
            problem = (
                f"the window's framebuffer is {fb[0]}x{fb[1]}, not {self.size[0]}x{self.size[1]} "
                f"(window size {win.width}x{win.height}: desktop HiDPI scaling or a window manager resizing it)"
            )
        elif loc != (scr.x, scr.y):
            problem = (
                f"the window opened at +{loc[0]}+{loc[1]}, not on the screen at +{scr.x}+{scr.y} "
                "(this system ignores the requested screen)"
            )
        if problem:
            self.close()
            raise ProjectorSetupError(f"{where}: {problem}; refusing to project")
        self.present(None)

    def _on_key_press(self, symbol: int, modifiers: int) -> bool:
        if symbol in (getattr(self._keys, k) for k in QUIT_KEYS):
            self._stop.set()
            return True  # handled: keeps pyglet's default Esc -> close
        return False

    def _on_close(self) -> bool:
        self._stop.set()
        return True  # the owner closes the window, never pyglet behind its back

    def _check(self) -> None:
        if threading.get_ident() != self._thread:
            raise RuntimeError("the projector window must be used from the thread that opened it")
        if self._window is None:
            raise DeviceError(f"projector {self.name} is closed")

    # ------------------------------------------------------------------ patterns

    def load(self, images: Sequence[np.ndarray]) -> None:
        """Upload the patterns (RGB uint8, (H, W, 3) = projector size) once, replacing earlier ones."""
        self._check()
        W, H = self.size
        checked = []
        for i, img in enumerate(images):
            img = np.asarray(img)
            if img.dtype != np.uint8 or img.shape != (H, W, 3):
                raise InputError(
                    f"pattern {i} is {img.dtype} {img.shape}; projector {self.name} needs uint8 ({H}, {W}, 3) RGB"
                )
            checked.append(img)
        self._sources = checked
        self._upload()

    def set_levels(self, gamma: float = 1.0, brightness: float = 1.0) -> None:
        """Change gamma/brightness; the loaded patterns are uploaded again through the new table."""
        self._check()
        self._lut = levels_lut(gamma, brightness)
        self.gamma, self.brightness = gamma, brightness
        if self._sources:
            self._upload()

    def __len__(self) -> int:
        return len(self._fbos)

    def _upload(self) -> None:
        import pyglet.image

        gl = self._gl
        self._window.switch_to()
        self._free_textures()
        W, H = self.size
        for img in self._sources:
            data = np.ascontiguousarray(apply_levels(img, self._lut)).tobytes()
            # Negative pitch: the first row of data is the top row (OpenGL counts rows from the bottom).
            tex = pyglet.image.ImageData(W, H, "RGB", data, pitch=-W * 3).get_texture()
            gl.glBindTexture(tex.target, tex.id)
            gl.glTexParameteri(tex.target, gl.GL_TEXTURE_MIN_FILTER, gl.GL_NEAREST)
            gl.glTexParameteri(tex.target, gl.GL_TEXTURE_MAG_FILTER, gl.GL_NEAREST)
            fbo = gl.GLuint()
            gl.glGenFramebuffers(1, ctypes.byref(fbo))
            gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, fbo)
            gl.glFramebufferTexture2D(gl.GL_READ_FRAMEBUFFER, gl.GL_COLOR_ATTACHMENT0, tex.target, tex.id, 0)
            complete = gl.glCheckFramebufferStatus(gl.GL_READ_FRAMEBUFFER) == gl.GL_FRAMEBUFFER_COMPLETE
            gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, 0)
            self._textures.append(tex)
            self._fbos.append(fbo.value)
            if not complete:
                self._free_textures()
                raise DeviceError(f"projector {self.name}: the OpenGL driver cannot read a {W}x{H} RGB texture")
        gl.glFinish()  # uploads done now, not during the first shows

    def _free_textures(self) -> None:
        gl = self._gl
        if self._fbos:
            ids = (gl.GLuint * len(self._fbos))(*self._fbos)
            gl.glDeleteFramebuffers(len(self._fbos), ids)
        for tex in self._textures:
            tex.delete()
        self._fbos, self._textures = [], []
        self.current = None

    # ------------------------------------------------------------------ showing

    def _draw(self, index: int | None) -> None:
        gl = self._gl
        gl.glBindFramebuffer(gl.GL_DRAW_FRAMEBUFFER, 0)
        if index is None:
            gl.glClearColor(0.0, 0.0, 0.0, 1.0)
            gl.glClear(gl.GL_COLOR_BUFFER_BIT)
            return
        W, H = self.size
        gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, self._fbos[index])
        gl.glBlitFramebuffer(0, 0, W, H, 0, 0, W, H, gl.GL_COLOR_BUFFER_BIT, gl.GL_NEAREST)
        gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, 0)

    def present(self, index: int | None) -> int:
        """Draw pattern `index` (None = black) and flip now; returns the flip time (monotonic ns)."""
        self._check()
        if index is not None and not 0 <= index < len(self._fbos):
            raise InputError(
                f"pattern index {index} is out of range: projector {self.name} has {len(self._fbos)} loaded"
            )
        win = self._window
        win.switch_to()
        win.dispatch_events()
        self._draw(index)
        win.flip()
        if self._finish:
            self._gl.glFinish()
        t = time.monotonic_ns()
        self.flips.append((index, t))
        self.current = index
        return t

    def show(self, index: int | None) -> int:
        """Projector protocol: pattern `index` (None = black) from the next refresh on; returns the flip time."""
        return self.present(index)

    def poll(self) -> bool:
        """Pump the window's events; True while nobody asked to stop (Esc, q, window close, request_stop)."""
        self._check()
        self._window.dispatch_events()
        return not self._stop.is_set()

    def request_stop(self) -> None:
        """Ask `run` to return after the current flip (safe from any thread)."""
        self._stop.set()

    @property
    def stop_requested(self) -> bool:
        return self._stop.is_set()

    def run(
        self,
        order: Sequence[int | None],
        hz: float | None = 60.0,
        *,
        seconds: float | None = None,
        frames: int | None = None,
        on_flip: Callable[[int, int | None, int], None] | None = None,
    ) -> FlipStats:
        """Show `order` cyclically at `hz` until `seconds`/`frames` are done or a stop is requested.

        hz paces flips by absolute deadlines (no drift); a flip later than one period resyncs the
        deadlines instead of bursting to catch up (counted as late). hz=None flips back to back,
        paced by vsync alone. on_flip(i, pattern, flip_time_ns) runs after every flip.
        Returns the interval statistics of this run's flips; leaves the last pattern shown.
        """
        self._check()
        if not order:
            raise InputError("run() needs at least one pattern index in its order")
        if hz is not None and not 0 < hz <= 1000:
            raise InputError(f"rate {hz!r} Hz is out of range (0 to 1000)")
        self._stop.clear()
        period = round(1e9 / hz) if hz else 0
        start = time.monotonic_ns()
        deadline = start
        times: list[int] = []
        i = 0
        while not self._stop.is_set():
            if frames is not None and i >= frames:
                break
            if seconds is not None and time.monotonic_ns() - start >= seconds * 1e9:
                break
            if period:
                wait = deadline - time.monotonic_ns()
                if wait > 0:
                    time.sleep(wait / 1e9)
            index = order[i % len(order)]
            t = self.present(index)
            times.append(t)
            if on_flip is not None:
                on_flip(i, index, t)
            i += 1
            if period:
                deadline += period
                if t > deadline:  # missed a slot: start again from now
                    deadline = t + period
        return flip_stats(times, hz)

    def stats(self, hz: float | None = None) -> FlipStats:
        """Interval statistics over the whole flip log."""
        return flip_stats([t for _, t in self.flips], hz)

    # ------------------------------------------------------------------ closing

    def close(self) -> None:
        """Free the textures and close the window (idempotent)."""
        if self._window is None:
            return
        if threading.get_ident() != self._thread:
            raise RuntimeError("the projector window must be closed from the thread that opened it")
        win, self._window = self._window, None
        try:
            win.switch_to()
            self._free_textures()
        finally:
            win.close()

    def __enter__(self) -> PygletProjector:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._window is None else f"{len(self._fbos)} pattern(s)"
        return f"PygletProjector({self.name!r}, {self.screen_name!r}, {self.size[0]}x{self.size[1]}, {state})"
