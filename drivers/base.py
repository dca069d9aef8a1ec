"""The small interfaces every device implements, and the name -> class registry the config uses.

Real devices (GenICam, V4L2, pyglet window, serial trigger box), the replay camera and the
virtual rig all implement these, so the capture loop never knows which one it drives.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from app.errors import DeviceError


@dataclass(frozen=True)
class Frame:
    """One camera image and its tags."""

    image: np.ndarray  # RGB uint8 or uint16, (H, W, 3)
    frame_id: int  # the device's frame counter (gaps = dropped frames)
    timestamp_ns: int  # device time if it has one, else host monotonic time
    pattern: int | None = None  # index of the pattern it saw, once the capture loop tags it
    trigger_count: int | None = None  # the trigger box's counter for this exposure, if known


class CameraTimeoutError(DeviceError):
    """No frame arrived within the timeout."""


@runtime_checkable
class Camera(Protocol):
    name: str

    def start(self) -> None: ...
    def grab(self, timeout_s: float = 1.0) -> Frame: ...
    def stop(self) -> None: ...
    def close(self) -> None: ...


@runtime_checkable
class Projector(Protocol):
    name: str
    size: tuple[int, int]  # (W, H)

    def load(self, images: Sequence[np.ndarray]) -> None: ...
    def show(self, index: int | None) -> None: ...  # None = black
    def close(self) -> None: ...


@runtime_checkable
class Trigger(Protocol):
    name: str

    def start(self, rate_hz: float) -> None: ...
    def stop(self) -> None: ...
    def counter(self) -> int: ...
    def close(self) -> None: ...


# name -> factory(**options); each driver module registers itself at import.
CAMERAS: dict[str, Callable[..., Camera]] = {}
PROJECTORS: dict[str, Callable[..., Projector]] = {}
TRIGGERS: dict[str, Callable[..., Trigger]] = {}


def register(kind: dict[str, Callable], name: str) -> Callable[[Callable], Callable]:
    def deco(factory: Callable) -> Callable:
        kind[name] = factory
        return factory

    return deco
