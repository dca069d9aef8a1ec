"""A working volume read from a file: [x0, x1, y0, y1, z0, z1] in camera mm, finite, each low bound below its high."""

from __future__ import annotations

import math

from core.errors import InputError


def working_volume_field(value: object, where: str) -> tuple[float, ...] | None:
    """value as six floats, None for None; anything else is an InputError naming `where` (file and field)."""
    if value is None:
        return None
    ok = (
        isinstance(value, list | tuple)
        and len(value) == 6
        and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        and all(value[i] < value[i + 1] for i in (0, 2, 4))
    )
    if not ok:
        rule = "[x0, x1, y0, y1, z0, z1] (mm, finite, x0 < x1, y0 < y1, z0 < z1)"
        raise InputError(f"{where} must be {rule}, found {value!r}")
    return tuple(float(v) for v in value)
