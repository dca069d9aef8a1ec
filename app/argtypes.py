"""argparse types for numbers with a sign rule: a bad value is refused before anything runs."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from core.errors import InputError


def _checked(kind: type, ok: Callable[[float], bool], rule: str) -> Callable[[str], int | float]:
    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {'a whole number' if kind is int else 'a number'}"
            ) from None
        if not ok(value) or value != value:  # value != value: NaN
            raise argparse.ArgumentTypeError(f"{text!r} must be {rule}")
        return value

    parse.__name__ = f"{rule.replace(' ', '_')}_{kind.__name__}"
    return parse


positive_int = _checked(int, lambda v: v > 0, "greater than 0")
non_negative_int = _checked(int, lambda v: v >= 0, "0 or more")
positive_float = _checked(float, lambda v: 0 < v < float("inf"), "greater than 0")
non_negative_float = _checked(float, lambda v: 0 <= v < float("inf"), "0 or more")


def volume_mm(text: str | None) -> tuple[float, ...] | None:
    """--volume-mm X0,X1,Y0,Y1,Z0,Z1 (camera mm): a working volume, or None."""
    if text is None:
        return None
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) != 6 or not all(v[i] < v[i + 1] for i in (0, 2, 4)):
        raise InputError(f"--volume-mm {text!r}: expected X0,X1,Y0,Y1,Z0,Z1 in mm with X0 < X1, Y0 < Y1, Z0 < Z1")
    return v
