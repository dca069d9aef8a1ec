"""The keys a config may have: a key slscan does not know is an error naming it and the nearest known one.

A typo (`captur:`, `chanels:`) used to be accepted and ignored, so the setting silently kept its default. Every
section whose keys slscan reads is listed here; `rig.KIND` options are checked by the driver they go to
(app/rig_devices.py make_device) and `sim:` by the virtual rig (drivers/sim/devices.py), which know their own.
"""

from __future__ import annotations

from pathlib import Path

from core.errors import InputError
from core.suggest import unknown_name_hint

# key -> its sub-keys (a set), or None for a value or a section checked elsewhere
SCHEMA: dict[str, set[str] | None] = {
    "rig": {"camera", "projector", "trigger"},
    "sim": None,
    "scheme": {"name", "k", "channels", "colors", "stripe_width", "segmentation", "motion"},
    "capture": {"rate_hz", "texture_every"},
    "depth_range_mm": None,
    "calibration": None,
    "board": None,
}


def unknown_key_message(path: Path, dotted: str, known: set[str]) -> str:
    prefix, _, key = dotted.rpartition(".")
    return f"{path}: key '{dotted}' is unknown{unknown_name_hint(key, known, f'{prefix}.' if prefix else '')}"


def check_config_keys(path: Path, data: dict) -> None:
    """InputError at the first key outside SCHEMA (top level, then each listed section's keys)."""
    for key in data:
        if key not in SCHEMA:
            raise InputError(unknown_key_message(path, str(key), set(SCHEMA)))
    for key, sub in SCHEMA.items():
        section = data.get(key)
        if sub is None or not isinstance(section, dict):  # (a section that is not a mapping: its reader says so)
            continue
        for name in section:
            if name not in sub:
                raise InputError(unknown_key_message(path, f"{key}.{name}", sub))
