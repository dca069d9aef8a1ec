"""Which cameras are there: GenICam devices per GenTL producer, and V4L2 device nodes.

`list_cameras()` returns one dict per camera, each with a `spec` that `--camera` accepts:
  {"driver": "genicam", "producer", "vendor", "model", "serial", "device_id", "name", "access", "spec"}
  {"driver": "v4l2", "device", "name", "spec"}
and one {"driver": "genicam", "producer": PATH or "", "error": MESSAGE} per producer that could
not be used (a bad `cti` path, none configured at all), so a lister can say what to check.
Nothing is opened: GenICam devices are enumerated (through the process's one Harvester),
V4L2 nodes are read from /dev and sysfs.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from core.errors import DeviceError
from drivers.camera.genicam import info_field
from drivers.camera.gentl import HUB, env_producers, producer_paths
from drivers.camera.v4l2 import list_v4l2_devices

# GenTL DEVICE_ACCESS_STATUS values
ACCESS = {0: "unknown", 1: "available", 2: "read-only", 3: "no access", 4: "busy", 5: "open", 6: "open read-only"}


def list_cameras(cti_paths: Sequence[str | os.PathLike] = (), use_env: bool = True, v4l2: bool = True) -> list[dict]:
    out: list[dict] = []
    files: list[str] = []
    for entry in cti_paths:
        try:
            files += producer_paths([str(entry)], use_env=False)
        except DeviceError as exc:
            out.append({"driver": "genicam", "producer": str(entry), "error": str(exc)})
    if use_env:
        files += env_producers()
    files = list(dict.fromkeys(files))
    if not files and not out:
        try:
            producer_paths([], use_env=use_env)
        except DeviceError as exc:
            out.append({"driver": "genicam", "producer": "", "error": str(exc)})
    if files:
        try:
            with HUB.lock:
                infos = HUB.device_infos(files)
                entries = [_genicam_entry(i) for i in infos]
        except Exception as exc:  # GenTL errors from a misbehaving producer must not hide the others
            out.append({"driver": "genicam", "producer": ", ".join(files), "error": str(exc).splitlines()[0]})
            entries = []
        out += entries
        seen = {e["producer"] for e in out}
        loaded = set(HUB.loaded_producers())
        HUB.release_if_idle()
        for f in files:
            if f not in seen and loaded and f not in loaded:
                out.append({"driver": "genicam", "producer": f, "error": f"{f}: the producer failed to open"})
    if v4l2:
        for dev in list_v4l2_devices():
            spec = f"v4l2:{dev['device']}"
            out.append({"driver": "v4l2", "device": dev["device"], "name": dev["name"], "spec": spec})
    return out


def _genicam_entry(info: Any) -> dict:
    try:
        producer = str(info.parent.parent.path_name)
    except Exception:
        producer = ""
    serial, dev_id = info_field(info, "serial_number"), info_field(info, "id_")
    try:
        access = ACCESS.get(int(info.access_status), str(info.access_status))
    except Exception:
        access = "unknown"
    select = f"serial={serial}" if serial else f"device_id={dev_id}"
    return {
        "driver": "genicam",
        "producer": producer,
        "vendor": info_field(info, "vendor"),
        "model": info_field(info, "model"),
        "serial": serial,
        "device_id": dev_id,
        "name": info_field(info, "display_name") or info_field(info, "user_defined_name"),
        "access": access,
        "spec": f"genicam:cti={producer},{select}" if producer else f"genicam:{select}",
    }
