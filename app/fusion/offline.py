"""Fusing a recorded dump: decode each sliding frame set in order, register it, integrate it."""

from __future__ import annotations

import bisect
import warnings
from collections.abc import Callable
from dataclasses import dataclass

from app.decode.pipeline import DepthRangeWarning, EmptyResultWarning, FrameSetDecoder
from app.framesets import group_frame_sets
from app.fusion.colour import scan_colour
from app.fusion.fuser import DEFAULT_VOXEL_MM, Fuser
from core.calibration import Calibration
from core.dump import Dump
from core.errors import InputError

MIN_SCANS = 2
MAX_DROPPED_IN_A_ROW = 10  # then tracking is lost: the model stops there


class TrackingLostError(InputError):
    """Registration failed on too many scans in a row; the fuser holds the model built until then."""

    def __init__(self, message: str, fuser: Fuser) -> None:
        super().__init__(message)
        self.fuser = fuser


@dataclass
class FuseOptions:
    voxel_mm: float = DEFAULT_VOXEL_MM
    volume_mm: tuple[float, ...] | None = None  # None: the dump's working_volume_mm, if it has one
    min_weight: float = 3.0
    max_dropped_in_a_row: int = MAX_DROPPED_IN_A_ROW
    motion: str = "auto"
    refine: bool = True  # register every scan again against the other views once all are tracked (refine.py)


def fuse_dump(
    dump: Dump,
    calibration: Calibration | None,
    options: FuseOptions,
    progress: Callable[[int, int], None] | None = None,
) -> Fuser:
    if calibration is None:
        raise InputError(f"{dump.folder}: the dump has no calibration: fusion needs one (give --calibration FILE)")
    if dump.scheme != "two-shot" and dump.scheme != "one-shot":
        raise InputError(f"{dump.folder}: a {dump.scheme} dump: fusion takes one-shot or two-shot scans")
    meta = dump.patterns_meta()
    tags = [(f.frame_id, f.pattern) for f in dump.frames]
    textures = dump.texture_indices()
    texture_tag = len(meta["images"]) if textures else None
    sets, _ = group_frame_sets(tags, dump.scheme, len(meta["images"]), sliding=True, texture_pattern=texture_tag)
    if len(sets) < MIN_SCANS:
        raise InputError(f"{dump.folder}: {len(sets)} complete frame set(s): fusion needs at least {MIN_SCANS} scans")
    rng = dump.depth_range_mm() or (100.0, 5000.0)
    volume = options.volume_mm
    if volume is None:
        volume = dump.working_volume_mm()
    fuser = Fuser(calibration, rng, volume, options.voxel_mm, min_weight=options.min_weight, keep=options.refine)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EmptyResultWarning)
        warnings.simplefilter("ignore", DepthRangeWarning)
        dec = FrameSetDecoder(dump.scheme, meta, calibration, rng, motion=options.motion, mosaic=dump.mosaic)
        for n, fs in enumerate(sets):
            frames = [dump.load_frame(i) for i in fs.indices]
            previous = dump.load_frame(fs.previous) if fs.previous is not None else None
            _, depth = dec.stripes_and_depth(frames, fs.newest_index, previous)
            newest = fs.indices[fs.newest_index]
            k = bisect.bisect_left(textures, fs.first) - 1  # the nearest texture frame before the set colours it
            texture = dump.load_frame(textures[k]) if k >= 0 else None
            scan = fuser.scan(depth, scan_colour(frames, texture), dump.frames[newest].frame_id)
            res = fuser.add(scan)
            if progress is not None:
                progress(n + 1, len(sets))
            if fuser.stats.dropped_in_a_row > options.max_dropped_in_a_row:
                raise TrackingLostError(
                    f"{dump.folder}: tracking lost at scan {n} (frame {scan.frame_id}): "
                    f"{fuser.stats.dropped_in_a_row} scans in a row failed to register (last: {res.reason})",
                    fuser,
                )
    if options.refine:
        fuser.refine()
    if fuser.stats.integrated < MIN_SCANS:
        raise TrackingLostError(
            f"{dump.folder}: only {fuser.stats.integrated} scan(s) registered: too few to build a model", fuser
        )
    return fuser
