"""Frame dumps, format `slscan-dump` version 1 (docs/formats.md).

The writer is crash-safe by construction: a frame's PNG is written whole under a temporary name, then
its one-line entry is appended to `dump.yaml` (whose `frames:` list is the last key), then the PNG is
renamed into place. After a kill the file ends, at worst, in a half-written line or an entry whose
frame is still under its temporary name; the reader drops both, so a dump is always readable up to its
last complete frame, and `repair_dump` recovers the renamed-too-late one. Repair deletes nothing: what
it takes out of `frames/` goes to `orphans/`, and the old index stays as `dump.yaml.bak`.
"""

from __future__ import annotations

import errno
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from core.calibration import Calibration
from core.depth_range_field import depth_range_field
from core.errors import InputError
from core.imageio import encode_png, read_rgb
from core.mosaic import mosaic_name
from core.paths import resolves_inside
from core.pattern_export import read_patterns, read_patterns_meta, write_patterns
from core.patterns import PatternSet
from core.wallclock import now_ns, parse_wall_clock, wall_clock_iso
from core.working_volume_field import working_volume_field
from core.yamlfile import parse_yaml

FORMAT = "slscan-dump"
VERSION = 1
INDEX = "dump.yaml"
# header key: the host's wall clock when the writer started (sidecars date a frame set from it and the camera's time)
RECORDED_KEY = "recorded_utc"
# header key: the pattern tag of a white-light texture frame, always len(images) of patterns.yaml: one past the
# patterns, so a reader that does not know it sees a tag outside the scheme and never pairs the frame
TEXTURE_KEY = "texture_pattern"
# header key: a rendered scene's working volume (camera mm), which fusion keeps of each scan (slscan sim render)
WORKING_VOLUME_KEY = "working_volume_mm"

# PNG settings by level, measured on a 640x480 stripe frame with sensor noise (one core, this machine):
#   0: stored, no filter       ~1 ms/frame, 900 KB  (the live default: keeps up at 60 Hz with room)
#   1: Huffman-only, Up filter ~11 ms/frame, 470 KB (half the disk, ~2/3 of a core at 60 Hz)
#   OpenCV's default (zlib level 1, adaptive filters) took ~21 ms/frame, 550 KB: too slow for 60 Hz.
PNG_LEVELS: dict[int, tuple[int, ...]] = {
    0: (cv2.IMWRITE_PNG_COMPRESSION, 0, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE),
    1: (
        cv2.IMWRITE_PNG_COMPRESSION,
        1,
        cv2.IMWRITE_PNG_STRATEGY,
        cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
        cv2.IMWRITE_PNG_FILTER,
        cv2.IMWRITE_PNG_FILTER_UP,
    ),
    **{lvl: (cv2.IMWRITE_PNG_COMPRESSION, lvl) for lvl in range(2, 10)},
}


class DumpWriteError(InputError):
    """Writing a frame failed (disk full, folder removed): frames written before it stay readable."""

    def __init__(self, message: str, errno_: int | None = None) -> None:
        super().__init__(message)
        self.errno = errno_

    @property
    def disk_full(self) -> bool:
        return self.errno in (errno.ENOSPC, errno.EDQUOT)


@dataclass(frozen=True)
class FrameRecord:
    file: str  # relative to the dump folder
    pattern: int  # index into the pattern set's images
    frame_id: int
    timestamp_ns: int
    recovered: str = ""  # RECOVERED_BY_CONTENT: --repair told the tag and timestamp from the frame's content


class DumpWriter:
    """Append tagged camera frames to a new dump folder (refuses to overwrite one)."""

    def __init__(
        self,
        folder: str | os.PathLike,
        patterns: PatternSet,
        calibration: Calibration | None = None,
        depth_range_mm: tuple[float, float] | None = None,
        extra: dict | None = None,
        png_level: int = 1,
        pattern_files: dict[str, bytes] | None = None,
        mosaic: str | None = None,
        texture: bool = False,
    ) -> None:
        """texture: frames tagged len(patterns) are white-light texture frames (header texture_pattern).
        pattern_files: the files of `patterns`' export, already encoded (the poses of a calibration
        capture share one pattern set: encoding its PNGs again for every pose cost ~2 s a pose). mosaic: the
        Bayer mosaic of a single-chip camera's raw frames, stored as they are, one channel (core/mosaic.py)."""
        self.mosaic = mosaic_name(mosaic, "mosaic")
        if png_level not in PNG_LEVELS:
            raise InputError(f"PNG compression level {png_level} must be 0..9")
        self._png = PNG_LEVELS[png_level]
        self.folder = Path(folder)
        if self.folder.exists() and (not self.folder.is_dir() or any(self.folder.iterdir())):
            raise InputError(f"{self.folder}: already exists; a dump is never overwritten (choose another --out)")
        try:
            (self.folder / "frames").mkdir(parents=True, exist_ok=True)
            (self.folder / "patterns").mkdir()
        except OSError as exc:
            raise InputError(f"{self.folder}: cannot create the dump folder ({exc.strerror})") from None
        self.n_patterns = len(patterns)
        if pattern_files is None:
            write_patterns(patterns, self.folder / "patterns")
        else:
            for name, data in pattern_files.items():
                (self.folder / "patterns" / name).write_bytes(data)
        header: dict = {"format": FORMAT, "version": VERSION, "scheme": patterns.scheme, "patterns": "patterns"}
        if calibration is not None:
            calibration.save(self.folder / "calibration.yaml")
            header["calibration"] = "calibration.yaml"
        if depth_range_mm is not None:
            header["depth_range_mm"] = [float(depth_range_mm[0]), float(depth_range_mm[1])]
        if self.mosaic is not None:
            header["mosaic"] = self.mosaic
        header[RECORDED_KEY] = wall_clock_iso(now_ns())
        self.texture_pattern = self.n_patterns if texture else None
        if texture:
            header[TEXTURE_KEY] = self.n_patterns
        header.update(extra or {})
        self._index = open(self.folder / INDEX, "w", encoding="utf-8")  # kept open: one line appended per frame
        self._index.write(yaml.safe_dump(header, sort_keys=False) + "frames:\n")
        self._index.flush()
        self.count = 0
        self._last_ts: int | None = None
        self._last_id: int | None = None

    def add(self, image: np.ndarray, pattern: int, frame_id: int, timestamp_ns: int) -> FrameRecord:
        if not 0 <= pattern < self.n_patterns and pattern != self.texture_pattern:
            raise ValueError(f"pattern index {pattern} outside 0..{self.n_patterns - 1}")
        if self._last_ts is not None and timestamp_ns < self._last_ts:
            raise ValueError(f"timestamp {timestamp_ns} ns goes back in time (last {self._last_ts} ns)")
        # the reader refuses what the writer would otherwise write: ids that do not increase, values past int64
        if self._last_id is not None and frame_id <= self._last_id:
            raise ValueError(f"frame id {frame_id} does not increase (last {self._last_id})")
        if not (0 <= frame_id <= MAX_ID and 0 <= timestamp_ns <= MAX_ID):
            raise ValueError(f"frame id {frame_id} or timestamp {timestamp_ns} ns outside 0..2^63 - 1")
        if (image.ndim == 2) != (self.mosaic is not None):
            what = f"mosaic {self.mosaic}" if self.mosaic else "no mosaic"
            raise DumpWriteError(
                f"{self.folder}: a {image.shape} frame in a dump with {what} (raw Bayer frames are (H, W))"
            )
        rel = f"frames/{self.count:06d}.png"
        tmp = self.folder / f"frames/{self.count:06d}.tmp.png"
        data = encode_png(image, self._png)
        record = FrameRecord(rel, int(pattern), int(frame_id), int(timestamp_ns))
        line = _index_line(record)
        indexed = False
        try:
            # The frame's bytes complete under the temporary name, then its entry, then the rename: a kill
            # between the two leaves an entry whose file is a complete .tmp.png, which --repair renames into
            # place (the entry holds the tag, which nothing else can recover).
            _write_file(tmp, data)
            self._index.write(line)
            self._index.flush()
            indexed = True
            os.replace(tmp, self.folder / rel)
        except OSError as exc:
            if not indexed:  # (an indexed frame stays for --repair: it is complete)
                _unlink_quietly(tmp)
            what = "disk full" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else exc.strerror
            raise DumpWriteError(
                f"{self.folder}: cannot write frame {self.count} ({what}); the {self.count} frames before it are kept",
                exc.errno,
            ) from None
        self.count += 1
        self._last_ts = record.timestamp_ns
        self._last_id = record.frame_id
        return record

    def close(self) -> None:
        if not self._index.closed:
            try:
                self._index.flush()
                os.fsync(self._index.fileno())
            except OSError:
                pass  # disk full: what reached the file is all there is; the reader copes with a short tail
            finally:
                try:
                    self._index.close()
                except OSError:
                    pass

    def __enter__(self) -> DumpWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class Dump:
    folder: Path
    meta: dict
    frames: list[FrameRecord]
    tail: list[FrameRecord] = field(default_factory=list)  # entries after the last complete frame (a killed writer)

    @property
    def dropped_tail(self) -> int:
        return len(self.tail)

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

    def working_volume_mm(self) -> tuple[float, ...] | None:
        """The scene's working volume (camera mm), which fusion keeps of each scan; None in a dump that has none
        (checked by read_dump)."""
        where = f"{self.folder / INDEX}: field '{WORKING_VOLUME_KEY}'"
        return working_volume_field(self.meta.get(WORKING_VOLUME_KEY), where)

    @property
    def mosaic(self) -> str | None:
        """The Bayer mosaic of the raw one-channel frames, None for RGB frames (checked by read_dump)."""
        return self.meta.get("mosaic")

    @property
    def recorded_ns(self) -> int | None:
        """The wall clock (ns since the epoch) when the writer started, None in a dump that does not say it."""
        v = self.meta.get(RECORDED_KEY)
        return None if v is None else parse_wall_clock(v, f"{self.folder / INDEX}: field '{RECORDED_KEY}'")

    @property
    def texture_pattern(self) -> int | None:
        """The tag of white-light texture frames (checked by read_dump), None in a dump that has none."""
        return self.meta.get(TEXTURE_KEY)

    def texture_indices(self) -> list[int]:
        """The indices among frames of the texture frames, in capture order (the tag checked against patterns.yaml:
        it must be one past the patterns, so that no frame set can take a texture frame)."""
        tag = self.texture_pattern
        if tag is None:
            return []
        n = len(self.patterns_meta()["images"])
        if tag != n:
            raise InputError(
                f"{self.folder / INDEX}: field '{TEXTURE_KEY}' is {tag} but {self.patterns_folder / 'patterns.yaml'} "
                f"has {n} images: it must be {n}, one past the patterns"
            )
        return [i for i, f in enumerate(self.frames) if f.pattern == tag]

    def wall_clock_ns(self, i: int) -> int | None:
        """Frame i's time on the wall clock: the recording's start plus the camera time since the first frame (the
        camera's clock may be its own: only differences of its timestamps are used), None without recorded_utc."""
        start = self.recorded_ns
        if start is None or not self.frames:
            return None
        return start + self.frames[i].timestamp_ns - self.frames[0].timestamp_ns

    def load_frame(self, i: int) -> np.ndarray:
        """Frame i: RGB (H, W, 3), or the raw Bayer frame (H, W) in a dump with a mosaic."""
        grey = self.mosaic is not None
        return read_rgb(self.folder / self.frames[i].file, grey=grey, colour=not grey)


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
        meta = parse_yaml(text)
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
    depth_range_field(meta.get("depth_range_mm"), f"{path}: field 'depth_range_mm'")
    working_volume_field(meta.get(WORKING_VOLUME_KEY), f"{path}: field '{WORKING_VOLUME_KEY}'")
    if meta.get("mosaic") is not None:
        if not isinstance(meta["mosaic"], str):
            raise InputError(f"{path}: field 'mosaic' must be one of RGGB, GRBG, GBRG, BGGR, found {meta['mosaic']!r}")
        meta["mosaic"] = mosaic_name(meta["mosaic"], f"{path}: field 'mosaic'")
    if meta.get(RECORDED_KEY) is not None:
        parse_wall_clock(meta[RECORDED_KEY], f"{path}: field '{RECORDED_KEY}'")
    tag = meta.get(TEXTURE_KEY)
    if tag is not None and (not isinstance(tag, int) or isinstance(tag, bool) or tag < 1):
        raise InputError(f"{path}: field '{TEXTURE_KEY}' must be the number of pattern images, found {tag!r}")
    raw = meta.get("frames") or []
    if not isinstance(raw, list):
        raise InputError(f"{path}: field 'frames' must be a list")
    frames: list[FrameRecord] = []
    for i, entry in enumerate(raw):
        if not isinstance(entry, dict) or not all(k in entry for k in ("file", "pattern", "frame_id", "timestamp_ns")):
            raise InputError(f"{path}: frames[{i}] needs file, pattern, frame_id and timestamp_ns")
        rec = FrameRecord(
            str(entry["file"]),
            _whole(entry, "pattern", MAX_PATTERN, path, i),
            _whole(entry, "frame_id", MAX_ID, path, i),
            _whole(entry, "timestamp_ns", MAX_ID, path, i),
            RECOVERED_BY_CONTENT if entry.get("recovered") == RECOVERED_BY_CONTENT else "",
        )
        _inside(folder, rec.file, f"frames[{i}].file")
        if frames and rec.frame_id <= frames[-1].frame_id:
            raise InputError(
                f"{path}: frames[{i}].frame_id {rec.frame_id} does not increase (frames[{i - 1}] has "
                f"{frames[-1].frame_id}): the index is out of capture order"
            )
        if frames and rec.timestamp_ns < frames[-1].timestamp_ns:
            raise InputError(f"{path}: frames[{i}].timestamp_ns goes back in time (before frames[{i - 1}]'s)")
        frames.append(rec)
    # A frame whose file is missing ends the readable part only if nothing after it exists.
    tail: list[FrameRecord] = []
    while frames and not (folder / frames[-1].file).is_file():
        tail.insert(0, frames.pop())
    for i, rec in enumerate(frames):
        if not (folder / rec.file).is_file():
            raise InputError(f"{folder / rec.file}: frame file listed in {path} (frames[{i}]) is missing")
    meta["frames"] = None
    return Dump(folder, meta, frames, tail)


RECOVERED_BY_CONTENT = "content"
MAX_ID = (1 << 63) - 1  # frame ids and timestamps are int64 everywhere downstream
MAX_PATTERN = 1 << 16  # a pattern index: far more patterns than any scheme projects


def _whole(entry: dict, key: str, top: int, path: Path, i: int) -> int:
    """entry[key] as an int in 0..top: a YAML integer, not a float (which int() would truncate) nor a bool."""
    v = entry[key]
    if not isinstance(v, int) or isinstance(v, bool):
        raise InputError(f"{path}: frames[{i}].{key} must be a whole number, found {v!r}")
    if not 0 <= v <= top:
        raise InputError(f"{path}: frames[{i}].{key} = {v} is out of range (0 to {top})")
    return v


def _index_line(r: FrameRecord) -> str:
    """A frame's one-line entry under `frames:` (the writer appends it, repair writes the list whole)."""
    mark = f", recovered: {r.recovered}" if r.recovered else ""
    return f"- {{file: {r.file}, pattern: {r.pattern}, frame_id: {r.frame_id}, timestamp_ns: {r.timestamp_ns}{mark}}}\n"


def _inside(folder: Path, rel: object, field_name: str) -> Path:
    """folder / rel, for a relative path that stays inside the folder once symlinks are resolved."""
    if not isinstance(rel, str) or not rel:
        raise InputError(f"{folder / INDEX}: field '{field_name}' must be a relative path")
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts:
        raise InputError(f"{folder / INDEX}: field '{field_name}' = {rel!r} leaves the dump folder")
    if not resolves_inside(folder, folder / p):
        raise InputError(f"{folder / INDEX}: field '{field_name}' = {rel!r} is a symlink that leaves the dump folder")
    return folder / p


def _write_file(path: Path, data: bytes) -> None:
    """Write bytes with os.write, so a full disk raises OSError(ENOSPC) here (cv2.imwrite only says False)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        view = memoryview(data)
        while view:
            n = os.write(fd, view)
            view = view[n:]
    finally:
        os.close(fd)


def _unlink_quietly(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


@dataclass(frozen=True)
class RepairReport:
    frames: int  # frames the repaired index lists
    dropped_entries: int  # index entries removed (half-written line, frame file missing or incomplete)
    recovered: int  # frames whose entry was written but not yet their rename: renamed into place, kept
    orphaned: int  # files taken out of frames/ into orphans/: partial frames, frames with no entry
    backup: str  # the old index, kept beside the new one
    reindexed: int = 0  # of the recovered: a complete frame with no entry, its tag told from its content

    def summary(self) -> str:
        return (
            f"{self.frames} frames readable ({self.recovered} recovered, {self.reindexed} of them re-indexed from "
            f"their content); dropped {self.dropped_entries} broken "
            f"index entr{'y' if self.dropped_entries == 1 else 'ies'}; {self.orphaned} file(s) moved to "
            f"{ORPHANS}/; the old index kept as {self.backup}"
        )


ORPHANS = "orphans"


def repair_dump(folder: str | os.PathLike) -> RepairReport:
    """Make a dump whose writer was killed clean: index = its readable frames, nothing else in frames/.

    Never makes a readable dump less readable and deletes nothing: the index is parsed as the reader parses
    it (any key order) and written whole beside the old one, which is kept as dump.yaml.bak (or .bak.N); a
    frame whose entry was written but not its rename is renamed into place when its PNG is complete; partial
    frames and frames with no entry move to orphans/. Refuses a dump whose frames/ or index leaves the folder
    (a symlink out), so nothing outside it is touched.
    """
    folder = Path(folder)
    dump = read_dump(folder)
    path = folder / INDEX
    frames_dir = folder / "frames"
    for p in (path, frames_dir):
        if p.is_symlink() or not resolves_inside(folder, p):
            raise InputError(f"{p}: is a symlink; --repair changes nothing through a symlink")
    listed = list(dump.frames)
    recovered = 0
    # the entries after the last complete frame (checked by read_dump): the one whose rename a kill prevented
    # is recovered
    for rec in dump.tail:
        final = folder / rec.file
        tmp = final.with_name(final.stem + ".tmp.png")
        ok_order = not listed or (rec.frame_id > listed[-1].frame_id and rec.timestamp_ns >= listed[-1].timestamp_ns)
        if not (ok_order and tmp.is_file() and not tmp.is_symlink() and _complete_png(tmp)):
            break
        os.replace(tmp, final)
        listed.append(rec)
        recovered += 1
    # a kill after the frame's bytes and before its entry leaves it complete under its temporary name with no
    # entry: re-indexed when its content says which pattern it saw and that pattern is the one due next
    reindexed = 0
    if not dump.tail:
        unindexed = frames_dir / f"{len(listed):06d}.tmp.png"
        rec = _recover_by_content(dump, listed, unindexed)
        if rec is not None:
            os.replace(unindexed, folder / rec.file)
            listed.append(rec)
            reindexed = 1
    header = {k: v for k, v in dump.meta.items() if k != "frames"}
    lines = [_index_line(r) for r in listed]
    backup = _free_name(folder, INDEX + ".bak")
    try:
        os.link(path, backup)  # (the old index's file itself: the rename below gives the new one its name)
    except OSError:  # a file system without hard links
        _write_file(backup, path.read_bytes())
    tmp_index = folder / (INDEX + ".repair")
    _write_file(tmp_index, (yaml.safe_dump(header, sort_keys=False) + "frames:\n" + "".join(lines)).encode())
    os.replace(tmp_index, path)
    keep = {(folder / r.file).resolve() for r in listed}
    strays = [p for p in sorted(frames_dir.iterdir()) if p.resolve() not in keep and (p.is_file() or p.is_symlink())]
    if strays:
        orphans = folder / ORPHANS
        orphans.mkdir(exist_ok=True)
        for p in strays:
            os.replace(p, _free_name(orphans, p.name))  # (a symlink moves as the link itself)
    return RepairReport(
        len(listed), dump.dropped_tail - recovered, recovered + reindexed, len(strays), backup.name, reindexed
    )


MIN_CONTENT_MATCH = 0.5  # the normalised correlation a re-indexed frame must reach with its pattern's last frame


def _recover_by_content(dump: Dump, listed: list[FrameRecord], path: Path) -> FrameRecord | None:
    """The entry of a complete frame that has none, from its content: it is the frame written after the last
    listed one, so it saw the pattern due next in the cycle (pattern + 1 mod the pattern count) if its content
    agrees: against the newest listed frame of each pattern (their mean removed), it must correlate best, and
    by at least MIN_CONTENT_MATCH, with that pattern's. Its frame id is the next one and its timestamp one median
    frame interval later, and the entry says it was recovered. None when any of this cannot be told."""
    if not listed or path.is_symlink() or not path.is_file() or not _complete_png(path):
        return None
    n = len(dump.patterns_meta()["images"])
    patterns = [r for r in listed if r.pattern < n]  # (texture frames, tagged n, follow no cycle)
    if not patterns or listed[-1].pattern >= n:
        return None
    due = (listed[-1].pattern + 1) % n
    newest: dict[int, int] = {}
    for i, r in enumerate(listed):
        if r.pattern < n:
            newest[r.pattern] = i
    try:
        grey = dump.mosaic is not None
        image = read_rgb(path, grey=grey, colour=not grey).astype(np.float32)
        refs = {p: dump.load_frame(i).astype(np.float32) for p, i in newest.items()}
    except InputError:
        return None
    if (n > 1 and len(refs) < 2) or any(r.shape != image.shape for r in refs.values()):
        return None
    if n > 1:
        mean = sum(refs.values()) / len(refs)
        x = (image - mean).ravel()

        def match(ref: np.ndarray) -> float:
            y = (ref - mean).ravel()
            return float(x @ y / (np.linalg.norm(x) * np.linalg.norm(y) + 1e-9))

        scores = {p: match(r) for p, r in refs.items()}
        best = max(scores, key=scores.get)
        if best != due or scores[best] < MIN_CONTENT_MATCH:
            return None
    stamps = [r.timestamp_ns for r in listed]
    step = int(np.median(np.diff(stamps))) if len(stamps) > 1 else 0  # (texture frames are camera frames too)
    last = listed[-1]
    name = f"frames/{path.name.removesuffix('.tmp.png')}.png"
    return FrameRecord(name, due, last.frame_id + 1, last.timestamp_ns + step, recovered=RECOVERED_BY_CONTENT)


def _complete_png(path: Path) -> bool:
    """Whether a PNG file is whole: its signature, and an IEND chunk ending it (a write cut short has none)."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
            f.seek(max(0, path.stat().st_size - 12))
            tail = f.read(12)
    except OSError:
        return False
    return head == b"\x89PNG\r\n\x1a\n" and tail[4:8] == b"IEND"


def _free_name(folder: Path, name: str) -> Path:
    """folder / name, or name.1, name.2, ... : the first that does not exist (nothing is overwritten)."""
    candidate = folder / name
    n = 0
    while candidate.exists() or candidate.is_symlink():
        n += 1
        candidate = folder / f"{name}.{n}"
    return candidate
