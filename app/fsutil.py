"""Writing folders all-or-nothing: build in a hidden sibling, then rename into place."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from core.errors import InputError


@contextlib.contextmanager
def atomic_directory(target: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary folder that becomes `target` only if the block succeeds.

    An existing non-empty `target` is refused unless overwrite=True, so nothing recorded is lost.
    """
    target = Path(target)
    check_output_folder(target, overwrite=overwrite)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.exists():
        try:
            parent.mkdir(parents=True)
        except OSError as exc:
            raise InputError(f"{target}: cannot create the parent folder ({exc.strerror})") from None
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".partial", dir=parent))
    except OSError as exc:
        raise InputError(f"{target}: cannot write here ({exc.strerror})") from None
    try:
        yield tmp
        if target.exists():
            shutil.rmtree(target)
        os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def check_output_folder(target: str | os.PathLike, need_bytes: int = 0, *, overwrite: bool = False) -> None:
    """Refuse, before any work, an output folder that could not be written: a symlink, something that is not a
    folder (a device such as /dev/full), a non-empty folder (unless overwrite), a place not writable, or a disk
    with less than need_bytes free. Nothing is created."""
    target = Path(target)
    if target.is_symlink():  # (an output is never written or removed through a symlink: it may lead anywhere)
        raise InputError(f"{target}: is a symlink; give the folder itself")
    if target.exists():
        if not target.is_dir():
            raise InputError(f"{target}: exists and is not a folder")
        if any(target.iterdir()) and not overwrite:
            raise InputError(f"{target}: folder exists and is not empty (choose another path or remove it)")
    existing = target.absolute().parent
    while not existing.exists():  # (the parents are made later: what matters is the first that exists)
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{target}: cannot write here ({existing} is not a writable folder)")
    if need_bytes > 0:
        free = shutil.disk_usage(existing).free
        if free < need_bytes:
            raise InputError(
                f"{target}: {free / 2**20:.0f} MB free on its disk, {need_bytes / 2**20:.0f} MB needed to start"
            )
