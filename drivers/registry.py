"""The driver registries, filled in one place: which modules register which kind of device.

Each driver module registers its factories in `drivers.base` (CAMERAS, PROJECTORS, TRIGGERS) when it
is imported; `load(kind)` imports every module of that kind, so a config section or a camera SPEC
can name any driver, real or simulated.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from drivers.base import CAMERAS, PROJECTORS, TRIGGERS

MODULES: dict[str, tuple[str, ...]] = {
    "camera": ("drivers.camera.genicam", "drivers.camera.v4l2", "drivers.camera.replay", "drivers.sim.devices"),
    "projector": ("drivers.projector.window", "drivers.sim.devices"),
    "trigger": ("drivers.trigger.serial_box", "drivers.sim.devices"),
}
REGISTRIES: dict[str, dict[str, Callable]] = {"camera": CAMERAS, "projector": PROJECTORS, "trigger": TRIGGERS}


def load(kind: str) -> dict[str, Callable]:
    """Import the drivers of `kind` (camera, projector or trigger); return its filled registry."""
    for module in MODULES[kind]:
        importlib.import_module(module)
    return REGISTRIES[kind]
