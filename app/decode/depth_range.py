"""What a depth range leaves the stripe decoders: a one-line diagnosis when it leaves them nothing.

A periodic stripe sequence repeats across the projector every `period * stripe_width` columns. The depth range
gives each camera pixel an interval of projector columns (Triangulator.column_range), and a chain of stripes takes
the copy of the sequence that puts its columns inside those intervals (app/decode/fast/chains.py, the copy vote).
Two ways that leaves nothing to decode, both independent of the scene:

- the interval holds two or more whole copies at (nearly) every pixel: every copy fits, no copy wins, and the whole
  frame decodes empty (the range 100-5000 mm on the virtual rig allows ~6);
- the interval misses the projector's image at every pixel: no stripe can come from inside the range.
"""

from __future__ import annotations

import numpy as np

from core.errors import InputError


def copy_columns(pattern_meta: dict) -> int | None:
    """Projector columns of one copy of a periodic stripe sequence; None for a scheme without copies (Gray code)."""
    period = pattern_meta.get("period")
    if period is None:
        return None
    return int(period) * int(pattern_meta.get("stripe_width", 1))


def check_depth_range(
    column_lo: np.ndarray,
    column_hi: np.ndarray,
    projector_width: int,
    copy_span: int | None,
    depth_range_mm: tuple[float, float],
) -> str | None:
    """Raise InputError if no pixel's column interval meets the projector's image; return a warning (one line) if
    the interval holds two or more copies of the sequence at most pixels, else None."""
    near, far = depth_range_mm
    lo = np.clip(column_lo, 0, projector_width - 1)
    hi = np.clip(column_hi, 0, projector_width - 1)
    with np.errstate(invalid="ignore"):
        seen = np.isfinite(lo) & np.isfinite(hi) & (column_hi >= 0) & (column_lo <= projector_width - 1)
    if not seen.any():
        raise InputError(
            f"depth range {near:g}-{far:g} mm: no camera pixel sees a projector column inside it "
            "(the scene is lit outside it: check depth_range_mm)"
        )
    if copy_span is None:
        return None
    copies = (hi - lo)[seen] / copy_span
    typical = float(np.median(copies))
    if typical < 2.0:
        return None
    return (
        f"depth range {near:g}-{far:g} mm allows {typical:.1f} copies of the stripe sequence at a typical pixel "
        f"(one copy is {copy_span} projector columns): no copy can be told from the others and nothing will be "
        "decoded; give depth_range_mm as the scene's working volume"
    )
