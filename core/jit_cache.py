"""Where slscan's numba cache lives: read by core.jit, which points numba there when imported, and by the test
set-up, which must know the folder without importing core.jit (that would fix numba's cache folder for good)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

PACKAGES = ("app", "core", "drivers", "calibration")  # the application's top-level packages, beside this one's


def cache_base() -> Path:
    """NUMBA_CACHE_DIR if set, else ~/.cache/slscan/numba (XDG_CACHE_HOME respected)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "slscan" / "numba"


def source_digest(root: Path | None = None) -> str:
    """sha256 (first 16 hex digits) over the path and text of every .py file under PACKAGES that mentions numba."""
    root = root or Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            text = path.read_bytes()
            if b"numba" in text:
                h.update(path.relative_to(root).as_posix().encode() + b"\0" + text + b"\0")
    return h.hexdigest()[:16]


def merge_cache_folder(src: Path, dst: Path) -> int:
    """Add the compiled kernels of numba cache folder `src` to `dst` (same layout: cache_base()'s); returns how many
    signatures were added. Two processes compiling different signatures of one function into one folder at once
    can leave an index naming the other's code (numba/numba#10128), so concurrent compiles go to folders of their
    own and are merged afterwards, one process at a time.

    numba keeps per function an index `<name>.nbi` (its version, then (source stamp, {signature key: data file}))
    and one `<name>.<n>.nbc` per signature. An index of another numba version or source stamp in dst is replaced
    by src's; signatures dst has already are kept. Reading an index unpickles numba types, which creates numba's
    CPU target: in a process that compiles, call this only after core.jit is imported (it sets the target's
    features first)."""
    import pickle
    import shutil

    from numba.core.serialize import dumps

    added = 0
    for index in sorted(src.rglob("*.nbi")):
        folder = dst / index.parent.relative_to(src)
        folder.mkdir(parents=True, exist_ok=True)
        version, (stamp, overloads) = _read_index(index, pickle)
        mine = _read_index(folder / index.name, pickle) if (folder / index.name).exists() else None
        if mine is None or mine[0] != version or mine[1][0] != stamp:
            merged: dict = {}
        else:
            merged = dict(mine[1][1])
        used = set(merged.values())
        for key, data_name in overloads.items():
            if key in merged:
                continue
            number = 1
            while (name := f"{index.stem}.{number}.nbc") in used:
                number += 1
            shutil.copy2(index.parent / data_name, folder / name)
            merged[key] = name
            used.add(name)
            added += 1
        part = folder / f"{index.name}.merging"
        with open(part, "wb") as f:  # the index last, whole (renamed into place): it never names missing data
            pickle.dump(version, f, protocol=-1)
            f.write(dumps((stamp, merged)))
        part.replace(folder / index.name)
    return added


def _read_index(path: Path, pickle) -> tuple:
    """(numba version, (source stamp, overloads)) of an index file (see merge_cache_folder)."""
    with open(path, "rb") as f:
        version = pickle.load(f)
        return version, pickle.loads(f.read())
