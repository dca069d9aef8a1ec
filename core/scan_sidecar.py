"""The `scan.yaml` sidecar (docs/formats.md, "Scan sidecar"): what one decoded frame set's files are.

Written beside every live snapshot (`scan.yaml`) and every frame set `slscan decode` writes (`scan_NNNNNN.yaml`):
the frames it came from (ids, camera timestamps, the host's wall clock), the units, the 16-bit PNG's depth scale,
the calibration (a copy beside it, and its digest) and the white-light texture frame that coloured the cloud.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from core.errors import InputError
from core.wallclock import parse_wall_clock
from core.yamlfile import parse_yaml

FORMAT = "slscan-scan"
VERSION = 1
FILE_KINDS = ("depth", "depth_png", "cloud", "stripes", "preview", "texture")


@dataclass(frozen=True)
class ScanInfo:
    """One scan's sidecar. files: kind (FILE_KINDS) -> a file name beside the sidecar."""

    scheme: str
    frame_ids: tuple[int, ...]  # the set's camera frame ids, in pattern order
    timestamps_ns: tuple[int, ...]  # their camera timestamps (device clock where the camera has one, else host's)
    camera_size: tuple[int, int]
    files: dict[str, str] = field(default_factory=dict)
    wall_clock_start: str | None = None  # ISO 8601 UTC of the set's first frame, None where not known
    depth_scale: float | None = None  # units per metre of the 16-bit PNG (Open3D's depth_scale), with depth_png
    calibration: str | None = None  # the calibration's copy beside the sidecar
    calibration_sha256: str | None = None  # core/depth_message.calibration_digest
    calibration_source: str | None = None  # where the calibration was read from (informative, never followed)
    texture_frame_id: int | None = None  # the white-light frame that coloured the cloud, None = the set's own frames
    source: str | None = None  # the dump or the rig the frames came from (informative)

    def as_dict(self) -> dict:
        d: dict = {
            "format": FORMAT,
            "version": VERSION,
            "scheme": self.scheme,
            "frame_ids": [int(i) for i in self.frame_ids],
            "timestamps_ns": [int(t) for t in self.timestamps_ns],
            "wall_clock_start": self.wall_clock_start,
            "units": "mm",
            "depth_none": 0,
            "camera_size": [int(v) for v in self.camera_size],
            "files": dict(self.files),
            "depth_scale": self.depth_scale,
            "calibration": self.calibration,
            "calibration_sha256": self.calibration_sha256,
            "calibration_source": self.calibration_source,
            "texture_frame_id": self.texture_frame_id,
            "source": self.source,
        }
        return d


def write_scan_info(path: str | os.PathLike, info: ScanInfo) -> None:
    try:
        Path(path).write_text(yaml.safe_dump(info.as_dict(), sort_keys=False), encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot write the scan sidecar ({exc.strerror})") from None


def read_scan_info(path: str | os.PathLike) -> ScanInfo:
    """A sidecar, checked field by field (one-line InputError naming the file and the field)."""
    path = Path(path)
    try:
        d = parse_yaml(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from None
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise InputError(f"{path}: field 'format' must be {FORMAT!r}")
    if d.get("version") != VERSION:
        raise InputError(f"{path}: field 'version' is {d.get('version')!r}, this slscan reads version {VERSION}")
    if d.get("units") != "mm":
        raise InputError(f"{path}: field 'units' must be 'mm'")

    def ints(key: str) -> tuple[int, ...]:
        v = d.get(key)
        if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
            raise InputError(f"{path}: field '{key}' must be a list of integers")
        return tuple(v)

    def optional(key: str, types: type | tuple[type, ...]) -> object:
        v = d.get(key)
        if v is not None and (not isinstance(v, types) or isinstance(v, bool)):
            raise InputError(f"{path}: field '{key}' has the wrong type ({type(v).__name__})")
        return v

    ids, stamps, size = ints("frame_ids"), ints("timestamps_ns"), ints("camera_size")
    if len(ids) != len(stamps) or not ids:
        raise InputError(f"{path}: fields 'frame_ids' and 'timestamps_ns' must be as long, and not empty")
    if len(size) != 2 or min(size) <= 0:
        raise InputError(f"{path}: field 'camera_size' must be [w, h], positive")
    files = d.get("files") or {}
    if not isinstance(files, dict) or not all(k in FILE_KINDS and isinstance(v, str) for k, v in files.items()):
        raise InputError(f"{path}: field 'files' must map {', '.join(FILE_KINDS)} to file names")
    for k, v in files.items():
        if Path(v).is_absolute() or ".." in Path(v).parts:
            raise InputError(f"{path}: field 'files.{k}' = {v!r} leaves the folder")
    scale = optional("depth_scale", (int, float))
    if scale is not None and not scale > 0:
        raise InputError(f"{path}: field 'depth_scale' must be positive (units per metre)")
    if "depth_png" in files and scale is None:
        raise InputError(f"{path}: field 'depth_scale' is needed with files.depth_png")
    wall = optional("wall_clock_start", str)
    if wall is not None:
        parse_wall_clock(wall, f"{path}: field 'wall_clock_start'")
    return ScanInfo(
        scheme=str(d.get("scheme")),
        frame_ids=ids,
        timestamps_ns=stamps,
        camera_size=(size[0], size[1]),
        files=dict(files),
        wall_clock_start=wall,  # type: ignore[arg-type]
        depth_scale=None if scale is None else float(scale),  # type: ignore[arg-type]
        calibration=optional("calibration", str),  # type: ignore[arg-type]
        calibration_sha256=optional("calibration_sha256", str),  # type: ignore[arg-type]
        calibration_source=optional("calibration_source", str),  # type: ignore[arg-type]
        texture_frame_id=optional("texture_frame_id", int),  # type: ignore[arg-type]
        source=optional("source", str),  # type: ignore[arg-type]
    )
