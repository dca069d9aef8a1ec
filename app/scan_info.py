"""The scan sidecar (core/scan_sidecar.py) of a frame set decoded from a dump, or of a live result."""

from __future__ import annotations

from collections.abc import Sequence

from core.calibration import Calibration
from core.depth_message import calibration_digest
from core.dump import Dump
from core.scan_sidecar import ScanInfo
from core.wallclock import monotonic_to_wall_ns, wall_clock_iso
from drivers.base import Frame

CALIBRATION_COPY = "calibration.yaml"  # the calibration's copy beside the sidecars


def dump_scan_info(
    dump: Dump,
    indices: Sequence[int],
    files: dict[str, str],
    calibration: Calibration | None,
    calibration_source: str | None,
    depth_scale: float | None,
    texture_index: int | None,
) -> ScanInfo:
    """indices: the set's frames (pattern order) among dump.frames; texture_index: the texture frame colouring it."""
    recs = [dump.frames[i] for i in indices]
    first = min(indices, key=lambda i: dump.frames[i].timestamp_ns)
    wall = dump.wall_clock_ns(first)
    return ScanInfo(
        scheme=dump.scheme,
        frame_ids=tuple(r.frame_id for r in recs),
        timestamps_ns=tuple(r.timestamp_ns for r in recs),
        camera_size=_size(calibration, dump, indices[0]),
        files=files,
        wall_clock_start=None if wall is None else wall_clock_iso(wall),
        depth_scale=depth_scale if "depth_png" in files else None,
        calibration=CALIBRATION_COPY if calibration is not None else None,
        calibration_sha256=calibration_digest(calibration) if calibration is not None else None,
        calibration_source=calibration_source,
        texture_frame_id=None if texture_index is None else dump.frames[texture_index].frame_id,
        source=str(dump.folder),
    )


def live_scan_info(
    scheme: str,
    frames: Sequence[Frame],
    arrival_ns: int,
    files: dict[str, str],
    calibration: Calibration,
    calibration_source: str | None,
    depth_scale: float | None,
    texture: Frame | None,
    source: str | None = None,
) -> ScanInfo:
    """frames: the set's (pattern order); arrival_ns: the host's monotonic time its newest frame arrived."""
    first = min(f.timestamp_ns for f in frames)
    newest = max(f.timestamp_ns for f in frames)
    # (the camera's clock may be its own: only the difference of its timestamps is used)
    wall = monotonic_to_wall_ns(arrival_ns) - (newest - first)
    return ScanInfo(
        scheme=scheme,
        frame_ids=tuple(f.frame_id for f in frames),
        timestamps_ns=tuple(f.timestamp_ns for f in frames),
        camera_size=tuple(calibration.camera_size),  # type: ignore[arg-type]
        files=files,
        wall_clock_start=wall_clock_iso(wall),
        depth_scale=depth_scale if "depth_png" in files else None,
        calibration=CALIBRATION_COPY,
        calibration_sha256=calibration_digest(calibration),
        calibration_source=calibration_source,
        texture_frame_id=None if texture is None else texture.frame_id,
        source=source,
    )


def _size(calibration: Calibration | None, dump: Dump, i: int) -> tuple[int, int]:
    if calibration is not None:
        w, h = calibration.camera_size
        return int(w), int(h)
    img = dump.load_frame(i)
    return int(img.shape[1]), int(img.shape[0])
