"""Camera specs (`--camera SPEC`) and config sections -> a Camera from the registry.

SPEC = DRIVER[:ITEM[,ITEM...]], each ITEM `key=value`; a first item without `=` is the driver's
main argument. Examples:
  genicam:index=0      genicam:serial=21234567      genicam:cti=/opt/vendor/x.cti,model=acA1300
  genicam:cti=viky,serial=0,pixel_format=Mono8      (viky = the genicam wheel's virtual producer)
  v4l2:/dev/video0     v4l2:0,fourcc=MJPG,width=1280,height=720,fps=60
  replay:DUMP          replay:DUMP,realtime=true,loop=true
  sim                  (the virtual rig's camera, drivers/sim)
Values stay strings here; each driver converts and checks its own options. A config section is
the same thing as a mapping: {driver: genicam, serial: "21234567", pixel_format: BayerRG8}.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from core.errors import InputError
from drivers.base import Camera

MAIN_ARGUMENT = {"v4l2": "device", "replay": "dump", "genicam": "device_id"}

TRUE = {"1", "true", "yes", "on"}
FALSE = {"0", "false", "no", "off"}


@dataclass(frozen=True)
class CameraSpec:
    driver: str
    options: dict[str, Any] = field(default_factory=dict)

    def __str__(self) -> str:
        items = ",".join(f"{k}={v}" for k, v in self.options.items())
        return f"{self.driver}:{items}" if items else self.driver


def parse_camera_spec(text: str) -> CameraSpec:
    text = text.strip()
    driver, _, rest = text.partition(":")
    driver = driver.strip().lower()
    if not driver:
        raise InputError(f"camera spec {text!r}: starts with no driver name (e.g. genicam:index=0, v4l2:0, sim)")
    options: dict[str, Any] = {}
    for i, item in enumerate(filter(None, (s.strip() for s in rest.split(",")))):
        key, eq, value = item.partition("=")
        if not eq:
            main = MAIN_ARGUMENT.get(driver)
            if i != 0 or main is None:
                raise InputError(f"camera spec {text!r}: {item!r} should be key=value")
            key, value = main, item
        key = key.strip().replace("-", "_")
        if not key.isidentifier():
            raise InputError(f"camera spec {text!r}: {key!r} is not an option name")
        if key in options:
            raise InputError(f"camera spec {text!r}: option {key!r} given twice")
        options[key] = value.strip()
    return CameraSpec(driver, options)


def as_bool(name: str, value: Any) -> bool:
    """A bool option from YAML (a bool) or a spec (a string)."""
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in TRUE:
        return True
    if text in FALSE:
        return False
    raise InputError(f"camera option {name}={value!r} must be true or false")


def load_camera_drivers() -> dict[str, Any]:
    """Import every camera driver so it registers itself (drivers.registry); return the registry."""
    from drivers import registry

    return registry.load("camera")


def open_camera(spec: str | CameraSpec | Mapping[str, Any]) -> Camera:
    """A camera from a SPEC string, a parsed CameraSpec, or a config mapping with a `driver` key."""
    if isinstance(spec, str):
        spec = parse_camera_spec(spec)
    elif isinstance(spec, Mapping):
        opts = dict(spec)
        driver = opts.pop("driver", None)
        if not isinstance(driver, str):
            raise InputError("camera config: missing key 'driver' (genicam, v4l2, replay or sim)")
        spec = CameraSpec(driver.lower(), opts)
    registry = load_camera_drivers()
    factory = registry.get(spec.driver)
    if factory is None:
        known = ", ".join(sorted(registry)) or "none"
        raise InputError(f"camera driver {spec.driver!r} is unknown (known: {known})")
    _check_options(spec, factory)
    return factory(**spec.options)


def _check_options(spec: CameraSpec, factory: Any) -> None:
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    unknown = [k for k in spec.options if k not in params]
    if unknown:
        known = ", ".join(k for k, p in params.items() if p.kind is not inspect.Parameter.VAR_POSITIONAL)
        raise InputError(f"camera driver {spec.driver!r} has no option {unknown[0]!r} (options: {known})")
