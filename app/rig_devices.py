"""A rig's devices from a config file's `rig:` section, by one rule for every command that opens them
(the live session, dump, replay, bench --live and the calibration wizard on a rig)."""

from __future__ import annotations

import contextlib
import importlib
from typing import Any

from app.config import Config
from app.errors import InputError

# importing these registers the real drivers (the sim ones register with drivers.sim.devices)
DRIVER_MODULES = {
    "camera": ("drivers.camera.spec",),
    "projector": ("drivers.projector.window",),
    "trigger": ("drivers.trigger.serial_box",),
}


def rig_driver(cfg: Config, kind: str, registry: dict, required: bool = True) -> tuple[str | None, dict]:
    """The `rig.KIND` section: its driver name, checked against the registry, and its options."""
    sec = cfg.section("rig").get(kind)
    if sec is None or sec == "none":
        if required:
            raise InputError(f"{cfg.path}: missing key 'rig.{kind}'")
        return None, {}
    if not isinstance(sec, dict):
        raise InputError(f"{cfg.path}: key 'rig.{kind}' must be a mapping with a 'driver'")
    name = cfg.get(f"rig.{kind}.driver", types=str)
    if name == "none" and not required:
        return None, {}
    if name != "sim":
        for mod in DRIVER_MODULES[kind]:
            with contextlib.suppress(ImportError):
                importlib.import_module(mod)
        if kind == "camera":
            from drivers.camera.spec import load_camera_drivers

            load_camera_drivers()
        if name not in registry:
            known = ", ".join(sorted({*registry, "sim"}))
            raise InputError(f"{cfg.path}: key 'rig.{kind}.driver': unknown driver {name!r} (known: {known})")
    return name, {k: v for k, v in sec.items() if k != "driver"}


def make_device(cfg: Config, kind: str, registry: dict, name: str, options: dict) -> Any:
    """Open the `rig.KIND` device; options the driver does not take are an error naming the key."""
    try:
        return registry[name](**options)
    except TypeError as exc:
        raise InputError(f"{cfg.path}: key 'rig.{kind}': bad options for driver {name!r} ({exc})") from None
