"""Settings: a rig (camera, projector, trigger drivers) and a scheme, from YAML.

`config/sim.yaml` (the virtual rig) is the default. Errors name the file and the key.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from app.config_keys import check_config_keys
from core.errors import InputError
from core.resources import CONFIG_DIR
from core.yamlfile import load_yaml_mapping

DEFAULT_CONFIG = CONFIG_DIR / "sim.yaml"


@dataclass
class Config:
    path: Path
    data: dict = field(repr=False)

    def section(self, key: str, required: bool = True) -> dict:
        value = self.data.get(key)
        if value is None:
            if required:
                raise InputError(f"{self.path}: missing key '{key}'")
            return {}
        if not isinstance(value, dict):
            raise InputError(f"{self.path}: key '{key}' must be a mapping")
        return value

    def get(self, dotted: str, default: object = ..., types: type | tuple[type, ...] | None = None) -> object:
        """A value by dotted key ('scheme.k'); missing without default -> error naming the key."""
        node: object = self.data
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                if default is ...:
                    raise InputError(f"{self.path}: missing key '{dotted}'")
                return default
            node = node[part]
        wanted = (types,) if isinstance(types, type) else types
        # (YAML's true/false are Python bools, which isinstance counts as ints: a number is never a bool)
        if types is not None and (not isinstance(node, types) or (isinstance(node, bool) and bool not in wanted)):
            names = types.__name__ if isinstance(types, type) else " or ".join(t.__name__ for t in types)
            raise InputError(f"{self.path}: key '{dotted}' must be {names}, found {node!r}")
        return node


def bundled_configs() -> list[str]:
    """The names of the configs that come with slscan (config/*.yaml), e.g. sim, sim_turntable."""
    return sorted(p.stem for p in CONFIG_DIR.glob("*.yaml"))


def load_config(path: str | os.PathLike | None = None) -> Config:
    """A config file; None is the virtual rig (sim.yaml). A bare name that is not a file names a bundled config
    (`--config sim_turntable`), so they work from any folder, installed or not."""
    path = Path(path) if path is not None else DEFAULT_CONFIG
    if not path.is_file() and path.parent == Path(".") and path.suffix in ("", ".yaml"):
        bundled = CONFIG_DIR / f"{path.stem}.yaml"
        if bundled.is_file():
            path = bundled
    if not path.is_file():
        raise InputError(f"{path}: config file not found (bundled configs: {', '.join(bundled_configs())})")
    data = load_yaml_mapping(path)
    check_config_keys(path, data)
    return Config(path, data)
