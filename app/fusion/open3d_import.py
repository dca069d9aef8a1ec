"""Open3D, the optional dependency of fusion: imported on first use, with a one-line error naming the extra."""

from __future__ import annotations

from types import ModuleType

from core.errors import InputError

INSTALL_HINT = "pip install 'slscan[fusion]'"


def open3d() -> ModuleType:
    """The open3d module, or InputError naming the extra that installs it."""
    try:
        import open3d as o3d
    except ImportError as exc:
        raise InputError(f"fusion needs Open3D, which is not installed ({exc}): {INSTALL_HINT}") from None
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d
