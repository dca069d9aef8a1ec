"""Where slscan's numba cache lives: read by core.jit, which points numba there when imported, and by the test
set-up, which must know the folder without importing core.jit (that would fix numba's cache folder for good)."""

from __future__ import annotations

import os
from pathlib import Path


def cache_base() -> Path:
    """NUMBA_CACHE_DIR if set, else ~/.cache/slscan/numba (XDG_CACHE_HOME respected)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "slscan" / "numba"
