"""A depth range read from a file or a config: [near, far] in mm, finite numbers with 0 < near < far."""

from __future__ import annotations

import math

from core.errors import InputError


def depth_range_field(value: object, where: str) -> tuple[float, float] | None:
    """value as (near, far), None for None; anything else is an InputError naming `where` (file and field)."""
    if value is None:
        return None
    ok = (
        isinstance(value, list | tuple)
        and len(value) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        and 0 < value[0] < value[1]
    )
    if not ok:
        raise InputError(f"{where} must be [near, far] with finite 0 < near < far, found {value!r}")
    return float(value[0]), float(value[1])
