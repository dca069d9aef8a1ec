"""The small interfaces every device implements, and the name -> class registry the config uses.

Real devices (GenICam, V4L2, pyglet window, serial trigger box), the replay camera and the
virtual rig all implement these, so the capture loop never knows which one it drives.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from core.errors import DeviceError


@dataclass(frozen=True)
class Frame:
    """One camera image and its tags."""

    image: np.ndarray  # RGB uint8 or uint16, (H, W, 3); a raw Bayer frame (H, W) where mosaic is set
    frame_id: int  # the device's frame counter (gaps = dropped frames)
    timestamp_ns: int  # device time if it has one, else host monotonic time
    pattern: int | None = None  # index of the pattern it saw, once the capture loop tags it
    trigger_count: int | None = None  # the trigger box's counter for this exposure, if known
    mosaic: str | None = None  # a single-chip camera's Bayer mosaic (core/mosaic.py) of a raw image, else None


class CameraTimeoutError(DeviceError):
    """No frame arrived within the timeout."""


@runtime_checkable
class Camera(Protocol):
    name: str
    device: str  # what messages call it: model and serial, device path, dump folder

    def start(self) -> None: ...
    def grab(self, timeout_s: float = 1.0) -> Frame: ...
    def stop(self) -> None: ...
    def close(self) -> None: ...


@runtime_checkable
class CountingCamera(Camera, Protocol):
    """A camera that counts what it delivered and lost (`stats`: a dataclass of int counters)."""

    stats: Any


@runtime_checkable
class Projector(Protocol):
    """Shows loaded patterns full-screen.

    `thread_bound`: every call but `request_stop` must come from the thread that opened it (a pyglet
    window); the capture loop then shows inline instead of from its projector thread, unless the
    projector is wrapped to be served by its owner (`app.owner_thread`).
    `stop_requested`: the operator closed the window or pressed Esc/q in it; the session ends cleanly.
    """

    name: str
    size: tuple[int, int]  # (W, H)
    thread_bound: bool

    def load(self, images: Sequence[np.ndarray]) -> None: ...
    def show(self, index: int | None) -> int | None:
        """Pattern `index` (None = black) from the next refresh on; the flip time (monotonic ns) if known."""
        ...

    def poll(self) -> bool:
        """Pump the window's events (between shows); True while nobody asked to stop."""
        ...

    def request_stop(self) -> None:
        """Ask the session to end (safe from any thread)."""
        ...

    @property
    def stop_requested(self) -> bool: ...
    def close(self) -> None: ...


@runtime_checkable
class Trigger(Protocol):
    name: str

    def start(self, rate_hz: float) -> None: ...
    def stop(self) -> None: ...
    def counter(self) -> int: ...
    def close(self) -> None: ...


@runtime_checkable
class PeekableTrigger(Trigger, Protocol):
    """A trigger that follows its own event lines: `peek_counter()` answers without asking the device.

    The capture loop peeks between its regular `counter()` queries (which notice a device gone silent).
    """

    def peek_counter(self) -> int: ...


# name -> factory(**options); each driver module registers itself at import.
CAMERAS: dict[str, Callable[..., Camera]] = {}
PROJECTORS: dict[str, Callable[..., Projector]] = {}
TRIGGERS: dict[str, Callable[..., Trigger]] = {}


def register(kind: dict[str, Callable], name: str) -> Callable[[Callable], Callable]:
    def deco(factory: Callable) -> Callable:
        kind[name] = factory
        return factory

    return deco
