"""A rig's devices from a config file's `rig:` section, by one rule for every command that opens them
(the live session, dump, replay, bench --live and the calibration wizard on a rig)."""

from __future__ import annotations

import inspect
from typing import Any

from app.config import Config
from core.errors import InputError
from core.suggest import unknown_name_hint
from drivers import registry as driver_registry


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
    driver_registry.load(kind)  # fills `registry`, the drivers.base registry of this kind
    if name not in registry:
        known = ", ".join(sorted(registry))
        raise InputError(f"{cfg.path}: key 'rig.{kind}.driver': unknown driver {name!r} (known: {known})")
    options = {k: v for k, v in sec.items() if k != "driver"}
    _check_options(cfg, kind, registry[name], options)
    return name, options


def _check_options(cfg: Config, kind: str, factory: Any, options: dict) -> None:
    """An option the driver's factory does not take is an error naming it and the nearest one it takes (a typo
    would otherwise surface only when the device opens, as a TypeError)."""
    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):  # (a factory without a signature: the call itself will say)
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return
    known = {p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    for key in options:
        if key not in known:
            hint = unknown_name_hint(str(key), known, f"rig.{kind}.")
            raise InputError(f"{cfg.path}: key 'rig.{kind}.{key}' is unknown to its driver{hint}")


def make_device(cfg: Config, kind: str, registry: dict, name: str, options: dict) -> Any:
    """Open the `rig.KIND` device; options the driver does not take are an error naming the key."""
    try:
        return registry[name](**options)
    except TypeError as exc:
        raise InputError(f"{cfg.path}: key 'rig.{kind}': bad options for driver {name!r} ({exc})") from None
