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
    if target.is_symlink():  # (an output is never written or removed through a symlink: it may lead anywhere)
        raise InputError(f"{target}: is a symlink; give the folder itself")
    if target.exists():
        if not target.is_dir():
            raise InputError(f"{target}: exists and is not a folder")
        if any(target.iterdir()) and not overwrite:
            raise InputError(f"{target}: folder exists and is not empty (choose another path or remove it)")
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
