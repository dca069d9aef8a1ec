"""Offline decoding of a dump's frame sets to files: the per-set work shared by `slscan decode`'s local
process pool and its Dask workers (app/cluster/), so both write the same bytes."""

from __future__ import annotations

import argparse
import bisect
import hashlib
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from app.decode.pipeline import DecodedSet, DepthRangeWarning, EmptyResultWarning, FrameSetDecoder
from app.decoded_set_files import CALIBRATION_COPY, write_decoded_set
from app.export import DEPTH_PNG_SCALE
from app.framesets import FrameIndexSet, FrameSetStats, group_frame_sets
from core.calibration import Calibration
from core.dump import Dump, read_dump
from core.errors import InputError


@dataclass(frozen=True)
class DecodeSettings:
    """Everything a process needs to decode one dump's sets (picklable: sent to pool and cluster workers)."""

    folder: str
    scheme: str
    meta: dict
    calibration: Calibration | None
    depth_range_mm: tuple[float, float] | None
    segmentation: str | None = None
    motion: str = "auto"
    png16: bool = False
    preview: bool = False
    depth_scale: float = DEPTH_PNG_SCALE  # units per metre of the 16-bit depth PNGs
    calibration_source: str | None = None  # the calibration file read (the sidecars name it)


@dataclass
class DumpPlan:
    """One dump read and grouped into frame sets, checked before anything is written."""

    dump: Dump
    settings: DecodeSettings
    sets: list[FrameIndexSet]
    stats: FrameSetStats
    n_frames: int
    calibration_digest: str  # sha256 of the calibration file used, "" without one (a manifest's field)


def plan_dump(
    folder: str | Path,
    calibration: str | None = None,
    *,
    disjoint: bool = False,
    segmentation: str | None = None,
    motion: str = "auto",
    png16: bool = False,
    preview: bool = False,
    depth_scale: float = DEPTH_PNG_SCALE,
) -> DumpPlan:
    """Read a dump and group its frame sets; a dump with no complete set is an InputError naming it."""
    dump = read_dump(folder)
    meta = dump.patterns_meta()
    if meta["scheme"] != dump.scheme:
        raise InputError(f"{dump.folder}: dump scheme {dump.scheme!r} but patterns.yaml says {meta['scheme']!r}")
    if calibration:
        cal, cal_file = Calibration.load(calibration), Path(calibration)
    else:
        cal = dump.calibration()
        cal_file = dump.folder / dump.meta["calibration"] if cal is not None else None
    n_patterns = len(meta["images"])
    tags = [(f.frame_id, f.pattern) for f in dump.frames]
    texture = n_patterns if dump.texture_indices() else None  # (checks the dump's texture tag)
    sets, stats = group_frame_sets(tags, dump.scheme, n_patterns, sliding=not disjoint, texture_pattern=texture)
    if not sets:
        raise InputError(
            f"{dump.folder}: no complete {dump.scheme} frame set among {len(tags)} frame(s) "
            f"(needs {n_patterns} consecutive frames tagged 0..{n_patterns - 1})"
        )
    settings = DecodeSettings(
        str(dump.folder),
        dump.scheme,
        meta,
        cal,
        dump.depth_range_mm(),
        segmentation,
        motion,
        png16,
        preview,
        depth_scale,
        str(cal_file.resolve()) if cal_file is not None else None,
    )
    digest = hashlib.sha256(cal_file.read_bytes()).hexdigest() if cal_file is not None else ""
    return DumpPlan(dump, settings, sets, stats, len(tags), digest)


def plan_dumps(args: argparse.Namespace, resolve: bool = False) -> list[DumpPlan]:
    """plan_dump of every DUMP of a `slscan decode` command line, with its options; resolve: absolute folders
    (for workers elsewhere, which resolve nothing against this process's folder)."""
    return [
        plan_dump(
            Path(d).resolve() if resolve else d,
            args.calibration,
            disjoint=args.disjoint,
            segmentation=getattr(args, "segmentation", None),
            motion=getattr(args, "motion", "auto"),
            png16=args.png16,
            preview=args.preview,
            depth_scale=args.depth_scale,
        )
        for d in args.dump
    ]


def quiet_opencv() -> None:
    # A corrupt PNG is reported by us, in one line naming the file; OpenCV's own log lines would
    # only add noise to stderr.
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)


def write_calibration_copy(plan: DumpPlan, folder: Path) -> None:
    """The calibration used, beside the sets' sidecars that name it (CALIBRATION_COPY), once per output folder."""
    if plan.settings.calibration is not None:
        partial = folder / f".partial-{os.getpid()}-{CALIBRATION_COPY}"  # (whole under its final name, or absent)
        plan.settings.calibration.save(partial)
        os.replace(partial, folder / CALIBRATION_COPY)


class SetDecoder:
    """A dump's reader and its FrameSetDecoder, built once per process (calibration tables, compiled kernels)."""

    def __init__(self, settings: DecodeSettings) -> None:
        quiet_opencv()
        warnings.simplefilter("ignore", EmptyResultWarning)  # counted and said once by the caller
        warnings.simplefilter("ignore", DepthRangeWarning)  # said once, by the caller
        self.settings = settings
        self.dump = read_dump(settings.folder)
        s = settings
        self.decoder = FrameSetDecoder(
            s.scheme, s.meta, s.calibration, s.depth_range_mm, s.segmentation, s.motion, self.dump.mosaic
        )
        self.textures = self.dump.texture_indices()

    def decode_set(self, n: int, fs: FrameIndexSet, out: Path, load: Callable[[int], np.ndarray] | None = None) -> int:
        """Decode set n into out/ (app/decoded_set_files.py); returns its count of valid pixels. load: frame index
        -> image (a caller's cache; default: read the dump's file)."""
        return int(self.decode_and_write(n, fs, out, load).stripes.valid.sum())

    def decode_and_write(
        self, n: int, fs: FrameIndexSet, out: Path, load: Callable[[int], np.ndarray] | None = None
    ) -> DecodedSet:
        """decode_set, returning the decoded set itself."""
        load = load or self.dump.load_frame
        dump, dec, s = self.dump, self.decoder, self.settings
        frames = [load(i) for i in fs.indices]
        where = ", ".join(str(dump.folder / dump.frames[i].file) for i in fs.indices)
        previous = load(fs.previous) if fs.previous is not None and dec.motion is not None else None
        k = bisect.bisect_left(self.textures, fs.first) - 1  # the nearest texture frame before the set colours it
        texture_index = self.textures[k] if k >= 0 else None
        texture = load(texture_index) if texture_index is not None else None
        res = dec.decode(frames, where=where, newest=fs.newest_index, previous=previous, texture=texture)
        write_decoded_set(
            out,
            n,
            res,
            dump,
            fs.indices,
            dec,
            texture_index,
            s.png16,
            s.preview,
            s.depth_range_mm,
            depth_scale=s.depth_scale,
            calibration_source=s.calibration_source,
        )
        return res


def output_subfolders(folders: list[Path]) -> list[str]:
    """Where each dump's files go under OUT: OUT itself (".") for one dump, OUT/<dump folder name>/ for several
    (two dumps of one name are refused: their files would mix)."""
    if len(folders) == 1:
        return ["."]
    names = [Path(f).resolve().name for f in folders]
    seen: dict[str, Path] = {}
    for name, folder in zip(names, folders, strict=True):
        if name in seen:
            raise InputError(f"{folder}: a second dump named {name!r} (after {seen[name]}): its outputs would mix")
        seen[name] = folder
    return names
