"""Frame dumps, format `slscan-dump` version 1 (ARCHITECTURE.md, File formats).

The writer is crash-safe by construction: a frame's PNG is written under a temporary name and
renamed into place, and only then is its one-line entry appended to `dump.yaml`, whose `frames:`
list is the last key. After a kill the file ends, at worst, in a half-written line that the
reader drops, so a dump is always readable up to its last complete frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from app.errors import InputError
from app.imageio import read_rgb, write_rgb
from app.pattern_export import read_patterns, read_patterns_meta, write_patterns
from app.patterns import PatternSet
from calibration.model import Calibration

FORMAT = "slscan-dump"
VERSION = 1
INDEX = "dump.yaml"


@dataclass(frozen=True)
class FrameRecord:
    file: str  # relative to the dump folder
    pattern: int  # index into the pattern set's images
    frame_id: int
    timestamp_ns: int


class DumpWriter:
    """Append tagged camera frames to a new dump folder (refuses to overwrite one)."""

    def __init__(
        self,
        folder: str | os.PathLike,
        patterns: PatternSet,
        calibration: Calibration | None = None,
        depth_range_mm: tuple[float, float] | None = None,
        extra: dict | None = None,
    ) -> None:
        self.folder = Path(folder)
        if self.folder.exists() and (not self.folder.is_dir() or any(self.folder.iterdir())):
            raise InputError(f"{self.folder}: already exists; a dump is never overwritten (choose another --out)")
        try:
            (self.folder / "frames").mkdir(parents=True, exist_ok=True)
            (self.folder / "patterns").mkdir()
        except OSError as exc:
            raise InputError(f"{self.folder}: cannot create the dump folder ({exc.strerror})") from None
        self.n_patterns = len(patterns)
        write_patterns(patterns, self.folder / "patterns")
        header: dict = {"format": FORMAT, "version": VERSION, "scheme": patterns.scheme, "patterns": "patterns"}
        if calibration is not None:
            calibration.save(self.folder / "calibration.yaml")
            header["calibration"] = "calibration.yaml"
        if depth_range_mm is not None:
            header["depth_range_mm"] = [float(depth_range_mm[0]), float(depth_range_mm[1])]
        header.update(extra or {})
        self._index = open(self.folder / INDEX, "w", encoding="utf-8")  # kept open: one line appended per frame
        self._index.write(yaml.safe_dump(header, sort_keys=False) + "frames:\n")
        self._index.flush()
        self.count = 0
        self._last_ts: int | None = None

    def add(self, image: np.ndarray, pattern: int, frame_id: int, timestamp_ns: int) -> FrameRecord:
        if not 0 <= pattern < self.n_patterns:
            raise ValueError(f"pattern index {pattern} outside 0..{self.n_patterns - 1}")
        if self._last_ts is not None and timestamp_ns < self._last_ts:
            raise ValueError(f"timestamp {timestamp_ns} ns goes back in time (last {self._last_ts} ns)")
        rel = f"frames/{self.count:06d}.png"
        tmp = self.folder / f"frames/{self.count:06d}.tmp.png"
        write_rgb(tmp, image)
        os.replace(tmp, self.folder / rel)
        record = FrameRecord(rel, int(pattern), int(frame_id), int(timestamp_ns))
        self._index.write(
            f"- {{file: {rel}, pattern: {record.pattern}, frame_id: {record.frame_id}, "
            f"timestamp_ns: {record.timestamp_ns}}}\n"
        )
        self._index.flush()
        self.count += 1
        self._last_ts = record.timestamp_ns
        return record

    def close(self) -> None:
        if not self._index.closed:
            self._index.flush()
            os.fsync(self._index.fileno())
            self._index.close()

    def __enter__(self) -> DumpWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class Dump:
    folder: Path
    meta: dict
    frames: list[FrameRecord]
    dropped_tail: int = 0  # entries after the last complete frame (a writer that was killed)

    @property
    def scheme(self) -> str:
        return self.meta["scheme"]

    @property
    def patterns_folder(self) -> Path:
        return self.folder / self.meta["patterns"]

    def patterns_meta(self) -> dict:
        return read_patterns_meta(self.patterns_folder)

    def patterns(self) -> PatternSet:
        return read_patterns(self.patterns_folder)

    def calibration(self) -> Calibration | None:
        rel = self.meta.get("calibration")
        return None if rel is None else Calibration.load(_inside(self.folder, rel, "calibration"))

    def depth_range_mm(self) -> tuple[float, float] | None:
        r = self.meta.get("depth_range_mm")
        return None if r is None else (float(r[0]), float(r[1]))

    def load_frame(self, i: int) -> np.ndarray:
        return read_rgb(self.folder / self.frames[i].file)


def read_dump(folder: str | os.PathLike) -> Dump:
    """Read `dump.yaml`, tolerating a half-written last line; check every path stays inside."""
    folder = Path(folder)
    path = folder / INDEX
    if not path.is_file():
        raise InputError(f"{path}: not found ({folder} is not a frame dump)")
    text = path.read_bytes().decode("utf-8", errors="replace")
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # a writer killed mid-line
    try:
        meta = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(meta, dict):
        raise InputError(f"{path}: expected a mapping at the top level")
    if meta.get("format") != FORMAT:
        raise InputError(f"{path}: field 'format' is {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("version") != VERSION:
        raise InputError(f"{path}: field 'version' is {meta.get('version')!r}, this slscan reads version {VERSION}")
    for key in ("scheme", "patterns"):
        if key not in meta:
            raise InputError(f"{path}: missing field '{key}'")
    _inside(folder, meta["patterns"], "patterns")
    if "calibration" in meta:
        _inside(folder, meta["calibration"], "calibration")
    rng = meta.get("depth_range_mm")
    if rng is not None and not (
        isinstance(rng, list) and len(rng) == 2 and all(isinstance(v, int | float) for v in rng) and 0 < rng[0] < rng[1]
    ):
        raise InputError(f"{path}: field 'depth_range_mm' must be [near, far] with 0 < near < far")
    raw = meta.get("frames") or []
    if not isinstance(raw, list):
        raise InputError(f"{path}: field 'frames' must be a list")
    frames: list[FrameRecord] = []
    for i, entry in enumerate(raw):
        try:
            rec = FrameRecord(
                str(entry["file"]), int(entry["pattern"]), int(entry["frame_id"]), int(entry["timestamp_ns"])
            )
        except (TypeError, KeyError, ValueError):
            raise InputError(f"{path}: frames[{i}] needs file, pattern, frame_id and timestamp_ns") from None
        _inside(folder, rec.file, f"frames[{i}].file")
        if rec.pattern < 0:
            raise InputError(f"{path}: frames[{i}].pattern is negative")
        frames.append(rec)
    # A frame whose file is missing ends the readable part only if nothing after it exists.
    dropped = 0
    while frames and not (folder / frames[-1].file).is_file():
        frames.pop()
        dropped += 1
    for i, rec in enumerate(frames):
        if not (folder / rec.file).is_file():
            raise InputError(f"{folder / rec.file}: frame file listed in {path} (frames[{i}]) is missing")
    meta["frames"] = None
    return Dump(folder, meta, frames, dropped)


def _inside(folder: Path, rel: object, field_name: str) -> Path:
    if not isinstance(rel, str) or not rel:
        raise InputError(f"{folder / INDEX}: field '{field_name}' must be a relative path")
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts:
        raise InputError(f"{folder / INDEX}: field '{field_name}' = {rel!r} leaves the dump folder")
    return folder / p
