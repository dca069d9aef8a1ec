"""GenTL producers and the process's one harvesters `Harvester`.

Measured on the development machine: a second `Harvester` in one process sees 0 devices
until the first is reset, and `Harvester.update()` destroys every open image acquirer. So the
whole process shares one Harvester through `HUB`; it re-enumerates only while no camera is open,
and refuses (clearly) to load a new producer while one is.

Producers come from explicit `cti:` entries (a .cti file, a folder of them, or `viky` for the
virtual producer that the `genicam` wheel ships) and from the standard GENICAM_GENTL64_PATH.
"""

from __future__ import annotations

import atexit
import ctypes
import importlib
import os
import threading
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from core.errors import DeviceError
from drivers.camera.errors import NoProducerError

ENV_VAR = "GENICAM_GENTL64_PATH"
VIKY = "viky"


# GenICam support is optional: `genicam` has no wheel for some platforms (macOS on arm64), where slscan installs
# without it (pyproject.toml) and everything but a GenICam camera works.
GENICAM_PACKAGES = ("genicam", "harvesters")


def require_genicam() -> None:
    """DeviceError (one line, naming the package) unless the GenICam packages import."""
    for name in GENICAM_PACKAGES:
        try:
            importlib.import_module(name)
        except ImportError:
            raise DeviceError(
                f"GenICam cameras need the Python package '{name}', which is not installed: "
                "pip install 'slscan[genicam]' (it has no wheel for some platforms, e.g. macOS on arm64)"
            ) from None


def viky_path() -> str:
    """The virtual GenTL producer inside the installed `genicam` package (three virtual cameras)."""
    require_genicam()
    import genicam

    return os.path.join(os.path.dirname(genicam.__file__), "viky.cti")


def check_producer(path: str | os.PathLike) -> str:
    """Return the absolute path if it is a loadable GenTL producer, else raise NoProducerError."""
    p = Path(path)
    if not p.is_file():
        raise NoProducerError(f"{p}: GenTL producer (.cti) not found (check the camera's `cti:` path)")
    try:
        lib = ctypes.CDLL(str(p.resolve()))
    except OSError as exc:
        reason = str(exc).split(": ")[-1]
        raise NoProducerError(f"{p}: not a loadable GenTL producer ({reason}); check the `cti:` path") from None
    if not hasattr(lib, "GCInitLib"):
        raise NoProducerError(f"{p}: a shared library but not a GenTL producer (no GCInitLib); check the `cti:` path")
    return str(p.resolve())


def _expand(entry: str) -> list[str]:
    if entry == VIKY:
        return [check_producer(viky_path())]
    p = Path(entry).expanduser()
    if p.is_dir():
        found = sorted(str(f) for f in p.glob("*.cti"))
        if not found:
            raise NoProducerError(f"{p}: folder holds no GenTL producer (*.cti); check the `cti:` path")
        return [check_producer(f) for f in found]
    return [check_producer(p)]


def env_producers(environ: dict[str, str] | None = None) -> list[str]:
    """Every *.cti in the folders of GENICAM_GENTL64_PATH (missing folders are skipped, as GenTL does)."""
    value = (environ if environ is not None else os.environ).get(ENV_VAR, "")
    out: list[str] = []
    for folder in filter(None, value.split(os.pathsep)):
        d = Path(folder)
        if d.is_file() and d.suffix == ".cti":
            out.append(str(d.resolve()))
        elif d.is_dir():
            out += [str(f.resolve()) for f in sorted(d.glob("*.cti"))]
    return out


def producer_paths(cti: str | Sequence[str] | None = None, use_env: bool = True) -> list[str]:
    """Explicit `cti` entries first, then GENICAM_GENTL64_PATH's; NoProducerError if none at all."""
    entries = [cti] if isinstance(cti, str | os.PathLike) else list(cti or [])
    paths: list[str] = []
    for e in entries:
        paths += _expand(str(e))
    if use_env:
        paths += env_producers()
    unique = list(dict.fromkeys(paths))
    if not unique:
        raise NoProducerError(
            f"no GenTL producer (.cti) found: set `cti:` in the camera config (e.g. genicam:cti=/opt/vendor/x.cti) "
            f"or {ENV_VAR} to the vendor's producer folder"
        )
    return unique


class _Hub:
    """The one Harvester of this process, shared by every GenICam camera and the device lister."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self._h: Any = None
        self._files: list[str] = []
        self._open = 0

    def _harvester(self) -> Any:
        if self._h is None:
            require_genicam()
            from harvesters.core import Harvester

            self._h = Harvester()
            self._h.timeout_for_update = 1000  # ms: device enumeration never hangs
        return self._h

    def device_infos(self, files: Iterable[str]) -> list[Any]:
        """harvesters DeviceInfo objects of all loaded producers, after loading `files`.

        Re-enumerates (finds re-plugged cameras) only while no camera is open, because
        `Harvester.update()` would destroy the open ones.
        """
        files = list(files)
        with self.lock:
            h = self._harvester()
            missing = [f for f in files if f not in self._files]
            if self._open == 0:
                self._files = list(dict.fromkeys(self._files + files))
                h.remove_files()
                for f in self._files:
                    h.add_file(f)
                h.update()
            elif missing:
                raise NoProducerError(
                    f"cannot load {missing[0]} while another GenICam camera is open in this process "
                    "(harvesters re-enumerates by closing them): give all cameras the same `cti:` list"
                )
            return list(h.device_info_list)

    def loaded_producers(self) -> list[str]:
        """Paths of the producers the Harvester actually opened (a bad .cti is skipped by harvesters)."""
        with self.lock:
            if self._h is None:
                return []
            return [p.path_name for p in getattr(self._h, "_producers", [])]

    def create(self, info: Any) -> Any:
        """Open the device as an ImageAcquirer (may raise genicam ResourceInUseException)."""
        with self.lock:
            ia = self._harvester().create(info)
            self._open += 1
            return ia

    def destroy(self, ia: Any) -> None:
        with self.lock:
            try:
                ia.destroy()
            finally:
                self._open = max(0, self._open - 1)
                ias = getattr(self._h, "_ias", None)
                if isinstance(ias, list) and ia in ias:
                    ias.remove(ia)  # harvesters keeps every acquirer it made; forget the destroyed one
                self.release_if_idle()

    def release_if_idle(self) -> None:
        """Close the producers when no camera is open (the next open re-enumerates in ~10 ms).

        Holding them would make any other Harvester in this process see 0 devices.
        """
        with self.lock:
            if self._open == 0 and self._h is not None and self._files:
                self._drop()

    def _drop(self) -> None:
        # Harvester.reset() runs a weakref finalizer, which works only once per object: a reset
        # Harvester is thrown away and the next use makes a fresh one.
        h, self._h = self._h, None
        self._files = []
        if h is not None:
            h.reset()

    @property
    def open_count(self) -> int:
        return self._open

    def reset(self) -> None:
        """Release everything (process exit, or tests that simulate a vanished producer)."""
        with self.lock:
            self._drop()
            self._open = 0


HUB = _Hub()
atexit.register(HUB.reset)
