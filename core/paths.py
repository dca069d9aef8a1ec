"""Paths read from a file must stay inside the folder the user gave: checked with their symlinks resolved."""

from __future__ import annotations

from pathlib import Path


def resolves_inside(folder: Path, path: Path) -> bool:
    """Whether path, its symlinks resolved, lies inside folder (itself resolved); False for a symlink loop."""
    try:
        return path.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError):  # (RuntimeError: a symlink loop on older Pythons)
        return False
