"""The calibration capture layout (docs/formats.md; stable, other tools write it):

    DIR/board.yaml          the board description (calibration/board.py)
    DIR/pose_000/ ...       one frame dump (format v1, scheme graycode, frames tagged with their
                            pattern index) per pose; the first frame tagged with each index is used
    DIR/response/           optional: flat colour levels for the colour response
                            (levels.yaml: {format: slscan-levels, version: 1, camera_gamma (optional),
                             frames: [{file, channel: R|G|B, level: 0..255}, ...]} + PNGs)

The reader checks the layout and reads pose by pose, so a long session never holds every frame.
"""

from __future__ import annotations

import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from calibration.board import FILENAME as BOARD_FILE
from calibration.board import Board, load_board
from core.calibration import Calibration
from core.dump import Dump, DumpWriter, read_dump
from core.errors import InputError
from core.imageio import read_rgb, write_rgb
from core.paths import resolves_inside
from core.patterns import PatternSet
from core.yamlfile import parse_yaml

POSE_RE = re.compile(r"^pose_(\d{3,})$")
RESPONSE_DIR = "response"
LEVELS_FILE = "levels.yaml"
LEVELS_FORMAT = "slscan-levels"
CHANNELS = "RGB"


@dataclass
class PoseFrames:
    """One pose's frames in pattern order and the Gray-code pattern description."""

    name: str
    frames: list[np.ndarray]  # frames[p] saw pattern p
    patterns_meta: dict  # patterns.yaml of the dump (size, frames roles, bits)

    @property
    def projector_size(self) -> tuple[int, int]:
        w, h = self.patterns_meta["size"]
        return int(w), int(h)

    def role_index(self, kind: str) -> int:
        for i, role in enumerate(self.patterns_meta["frames"]):
            if role.get("kind") == kind:
                return i
        raise InputError(f"{self.name}: the Gray-code patterns have no '{kind}' frame")

    @property
    def white(self) -> np.ndarray:
        return self.frames[self.role_index("white")]


@dataclass
class Capture:
    folder: Path
    board: Board
    poses: list[str]  # folder names, sorted

    def pose_dump(self, name: str) -> Dump:
        return read_dump(self.folder / name)

    def read_pose(self, name: str) -> PoseFrames:
        dump = self.pose_dump(name)
        where = self.folder / name
        if dump.scheme != "graycode":
            raise InputError(f"{where}: scheme is {dump.scheme!r}, a calibration pose needs 'graycode'")
        meta = dump.patterns_meta()
        n = len(meta["images"])
        first: dict[int, int] = {}
        for i, rec in enumerate(dump.frames):
            if rec.pattern >= n:
                raise InputError(f"{where}: frame {rec.file} is tagged pattern {rec.pattern}, only {n} patterns")
            first.setdefault(rec.pattern, i)
        missing = [p for p in range(n) if p not in first]
        if missing:
            raise InputError(
                f"{where}: no frame tagged with pattern {missing[0]} ({len(missing)} of {n} patterns missing)"
            )
        frames = [dump.load_frame(first[p]) for p in range(n)]
        shapes = {f.shape for f in frames}
        if len(shapes) != 1:
            raise InputError(f"{where}: frames have different sizes {sorted(shapes)}")
        return PoseFrames(name, frames, meta)

    def true_calibration(self) -> Calibration | None:
        """The true calibration a simulated capture carries (dump field `calibration_is_truth`), else None.

        A real rig's dump carries the calibration that was in use, which is no truth to score against.
        """
        if not self.poses:
            return None
        dump = self.pose_dump(self.poses[0])
        return dump.calibration() if dump.meta.get("calibration_is_truth") is True else None

    def has_response(self) -> bool:
        return (self.folder / RESPONSE_DIR / LEVELS_FILE).is_file()

    def read_response(self) -> list[tuple[str, int, np.ndarray]]:
        return read_levels(self.folder / RESPONSE_DIR)

    def response_camera_gamma(self) -> float | None:
        """The camera gamma recorded with the levels (None: unknown, take the camera as linear)."""
        try:
            doc = parse_yaml((self.folder / RESPONSE_DIR / LEVELS_FILE).read_text())
        except (OSError, yaml.YAMLError, UnicodeDecodeError):
            return None
        g = doc.get("camera_gamma") if isinstance(doc, dict) else None
        return float(g) if isinstance(g, int | float) and not isinstance(g, bool) and 0.1 <= g <= 10 else None


def open_capture(folder: str | os.PathLike) -> Capture:
    """Check that `folder` is a calibration capture; the error says what is missing."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder (expected a calibration capture: board.yaml + pose_000/ ...)")
    if not (folder / BOARD_FILE).is_file():
        raise InputError(f"{folder}: not a calibration capture (no {BOARD_FILE}; expected board.yaml + pose_000/ ...)")
    board = load_board(folder / BOARD_FILE)
    poses = sorted(p.name for p in folder.iterdir() if p.is_dir() and POSE_RE.match(p.name))
    if not poses:
        raise InputError(f"{folder}: not a calibration capture (no pose_000/ folders)")
    for name in poses:
        if not (folder / name / "dump.yaml").is_file():
            raise InputError(f"{folder / name}: not a frame dump (no dump.yaml)")
    return Capture(folder, board, poses)


class CaptureWriter:
    """Writes a capture folder: board.yaml, then one dump per pose as poses are accepted."""

    def __init__(self, folder: str | os.PathLike, board: Board, patterns: PatternSet) -> None:
        self.folder = Path(folder)
        if self.folder.exists() and (not self.folder.is_dir() or any(self.folder.iterdir())):
            raise InputError(f"{self.folder}: already exists; a capture is never overwritten (choose another folder)")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{self.folder}: cannot create the capture folder ({exc.strerror})") from None
        board.save(self.folder / BOARD_FILE)
        self.patterns = patterns
        self.count = 0
        self._frame_id = 0
        self._pattern_files: dict[str, bytes] | None = None  # the first pose's pattern export, reused

    def add_pose(
        self,
        frames: list[np.ndarray],
        calibration: Calibration | None = None,
        timestamps_ns: list[int] | None = None,
        calibration_is_truth: bool = False,
        frame_ids: list[int] | None = None,
    ) -> str:
        """Write one pose (frames[p] saw pattern p); returns its folder name.

        frame_ids / timestamps_ns: the camera's, when the frames come from a camera (else numbered here).
        """
        if len(frames) != len(self.patterns):
            raise ValueError(f"{len(frames)} frames for {len(self.patterns)} patterns")
        name = f"pose_{self.count:03d}"
        extra = {"calibration_is_truth": True} if calibration is not None and calibration_is_truth else None
        with DumpWriter(
            self.folder / name, self.patterns, calibration, extra=extra, pattern_files=self._pattern_files
        ) as w:
            for p, img in enumerate(frames):
                ts = timestamps_ns[p] if timestamps_ns else self._frame_id * 16_666_667
                w.add(img, p, frame_ids[p] if frame_ids else self._frame_id, ts)
                self._frame_id += 1
        if self._pattern_files is None:
            self._pattern_files = {f.name: f.read_bytes() for f in sorted((self.folder / name / "patterns").iterdir())}
        self.count += 1
        return name

    def remove_last_pose(self) -> str | None:
        """Undo: delete the last pose folder (the wizard's undo key)."""
        if self.count == 0:
            return None
        self.count -= 1
        name = f"pose_{self.count:03d}"
        shutil.rmtree(self.folder / name, ignore_errors=True)
        return name

    def write_response(self, levels: list[tuple[str, int, np.ndarray]], camera_gamma: float | None = None) -> None:
        write_levels(self.folder / RESPONSE_DIR, levels, camera_gamma)


def write_levels(folder: Path, levels: list[tuple[str, int, np.ndarray]], camera_gamma: float | None = None) -> None:
    folder.mkdir(parents=True, exist_ok=False)
    entries = []
    for i, (channel, level, img) in enumerate(levels):
        name = f"{i:03d}_{channel}_{level:03d}.png"
        write_rgb(folder / name, img)
        entries.append({"file": name, "channel": channel, "level": int(level)})
    doc: dict = {"format": LEVELS_FORMAT, "version": 1}
    if camera_gamma is not None:
        doc["camera_gamma"] = float(camera_gamma)  # known camera response (the virtual rig's)
    doc["frames"] = entries
    (folder / LEVELS_FILE).write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))


def read_levels(folder: Path) -> list[tuple[str, int, np.ndarray]]:
    path = folder / LEVELS_FILE
    try:
        doc = parse_yaml(path.read_text())
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not readable ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict) or doc.get("format") != LEVELS_FORMAT:
        raise InputError(f"{path}: field 'format' must be {LEVELS_FORMAT!r}")
    out = []
    for i, e in enumerate(doc.get("frames") or []):
        level = e.get("level") if isinstance(e, dict) else None
        if (
            not isinstance(e, dict)
            or e.get("channel") not in tuple(CHANNELS)
            or not isinstance(level, int)
            or isinstance(level, bool)
            or not 0 <= level <= 255
        ):
            raise InputError(f"{path}: frames[{i}] needs file, channel (R, G or B) and level (0..255)")
        f = e.get("file")
        if not isinstance(f, str) or Path(f).is_absolute() or ".." in Path(f).parts:
            raise InputError(f"{path}: frames[{i}].file must be a file name inside {folder}")
        if not resolves_inside(folder, folder / f):
            raise InputError(f"{path}: frames[{i}].file = {f!r} is a symlink that leaves {folder}")
        out.append((e["channel"], int(e["level"]), read_rgb(folder / f)))
    if not out:
        raise InputError(f"{path}: no frames listed")
    return out
