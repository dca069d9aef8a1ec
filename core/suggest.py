"""The known name nearest a mistyped one, for "did you mean" in an error message."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def nearest(name: str, known: Iterable[str]) -> str | None:
    """The known name most like `name` (difflib's ratio >= 0.6), None if none is close."""
    close = difflib.get_close_matches(name, sorted(known), n=1, cutoff=0.6)
    return close[0] if close else None


def unknown_name_hint(name: str, known: Iterable[str], prefix: str = "") -> str:
    """ ": did you mean 'PREFIXguess'?" if one is close, else " (known: a, b, ...)"."""
    known = sorted(known)
    guess = nearest(name, known)
    return f": did you mean '{prefix}{guess}'?" if guess else f" (known: {', '.join(known)})"
