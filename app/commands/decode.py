"""`slscan decode DUMP --out OUT`: decode every complete frame set of a dump to depth, cloud and stripes."""

from __future__ import annotations

import argparse
import bisect
import os
import sys
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2

from app.argtypes import non_negative_int, positive_float
from app.decode.pipeline import DepthRangeWarning, EmptyResultWarning, FrameSetDecoder
from app.decoded_set_files import CALIBRATION_COPY, write_decoded_set
from app.export import DEPTH_PNG_SCALE
from app.framesets import FrameIndexSet, group_frame_sets
from app.fsutil import atomic_directory
from core.calibration import Calibration
from core.dump import Dump, read_dump
from core.errors import InputError

HELP = "decode a frame dump offline: depth TIFF, PLY cloud and stripe PNG per frame set"

EPILOG = """\
examples:
  slscan decode rec/ --out out/                     # calibration and depth range from the dump
  slscan decode rec/ --out out/ --calibration cal.yaml --workers 2 --png16 --preview

Frame sets come from the frames' pattern tags: a two-shot set is two frames with consecutive
frame_id tagged {0, 1} in either order (pairs slide: 1-2, 2-3, ...); a gap or a wrong tag is never
decoded. Without a calibration only the stripe PNGs are written.
"""

_STATE: dict = {}


MAX_WORKERS_PER_CORE = 2


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "decode", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("dump", metavar="DUMP", help="frame dump folder (format slscan-dump v1)")
    p.add_argument("--out", required=True, metavar="OUT", help="output folder (must not exist or be empty)")
    p.add_argument("--calibration", metavar="FILE", help="calibration YAML (default: the dump's own)")
    p.add_argument("--workers", type=non_negative_int, default=0, metavar="N", help="processes (default: all cores)")
    p.add_argument("--disjoint", action="store_true", help="two-shot: disjoint pairs (1-2, 3-4) instead of sliding")
    p.add_argument(
        "--segmentation",
        choices=("runs", "events", "both"),
        help="two-shot stripes: code runs (default), zero crossings, or both merged (a little more coverage "
        "on grazing surfaces, twice the time)",
    )
    p.add_argument(
        "--motion",
        choices=("auto", "off"),
        default="auto",
        help="two-shot: auto (default) decodes a pair's newest frame alone where the scene moved since the frame "
        "before the pair; off decodes every pair from the sign of its difference",
    )
    p.add_argument(
        "--png16",
        action="store_true",
        help="also write depth_NNNNNN.png (16-bit; units per metre: --depth-scale, stated in scan_NNNNNN.yaml)",
    )
    p.add_argument(
        "--depth-scale",
        type=positive_float,
        default=DEPTH_PNG_SCALE,
        metavar="S",
        help=f"units per metre of --png16 (Open3D's depth_scale; default {DEPTH_PNG_SCALE:g} = 0.1 mm, 1000 = mm)",
    )
    p.add_argument("--preview", action="store_true", help="also write preview_NNNNNN.png (colourised depth)")
    p.set_defaults(func=run)


def _quiet_opencv() -> None:
    # A corrupt PNG is reported by us, in one line naming the file; OpenCV's own log lines would
    # only add noise to stderr.
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)


def _init(
    folder: str,
    scheme: str,
    meta: dict,
    cal: Calibration | None,
    rng: tuple | None,
    seg: str | None = None,
    motion: str = "auto",
    outputs: dict | None = None,
) -> None:
    """outputs: depth_scale (of --png16), calibration_source (for the sidecars)."""
    _quiet_opencv()
    warnings.simplefilter("ignore", EmptyResultWarning)
    warnings.simplefilter("ignore", DepthRangeWarning)  # said once, by run()
    _STATE["dump"] = read_dump(folder)
    _STATE["decoder"] = FrameSetDecoder(scheme, meta, cal, rng, seg, motion, _STATE["dump"].mosaic)
    _STATE["range"] = rng
    _STATE["textures"] = _STATE["dump"].texture_indices()
    _STATE["outputs"] = {"depth_scale": DEPTH_PNG_SCALE, "calibration_source": None, **(outputs or {})}


def _work(job: tuple[int, FrameIndexSet, str, bool, bool]) -> tuple[int, int]:
    n, fs, out, png16, preview = job
    dump: Dump = _STATE["dump"]
    dec: FrameSetDecoder = _STATE["decoder"]
    frames = [dump.load_frame(i) for i in fs.indices]
    where = ", ".join(str(dump.folder / dump.frames[i].file) for i in fs.indices)
    previous = dump.load_frame(fs.previous) if fs.previous is not None and dec.motion is not None else None
    textures = _STATE["textures"]
    k = bisect.bisect_left(textures, fs.first) - 1  # the nearest texture frame before the set colours it
    texture_index = textures[k] if k >= 0 else None
    texture = dump.load_frame(texture_index) if texture_index is not None else None
    res = dec.decode(frames, where=where, newest=fs.newest_index, previous=previous, texture=texture)
    opts = _STATE["outputs"]
    write_decoded_set(Path(out), n, res, dump, fs.indices, dec, texture_index, png16, preview, _STATE["range"], **opts)
    return n, int(res.stripes.valid.sum())


def run(args: argparse.Namespace) -> int:
    _quiet_opencv()
    dump = read_dump(args.dump)
    meta = dump.patterns_meta()
    if meta["scheme"] != dump.scheme:
        raise InputError(f"{dump.folder}: dump scheme {dump.scheme!r} but patterns.yaml says {meta['scheme']!r}")
    cal = Calibration.load(args.calibration) if args.calibration else dump.calibration()
    rng = dump.depth_range_mm()
    n_patterns = len(meta["images"])
    tags = [(f.frame_id, f.pattern) for f in dump.frames]
    texture = n_patterns if dump.texture_indices() else None  # (checks the dump's texture tag)
    sets, stats = group_frame_sets(tags, dump.scheme, n_patterns, sliding=not args.disjoint, texture_pattern=texture)
    if not sets:
        raise InputError(
            f"{dump.folder}: no complete {dump.scheme} frame set among {len(tags)} frame(s) "
            f"(needs {n_patterns} consecutive frames tagged 0..{n_patterns - 1})"
        )
    # Fail early, in this process, on the first set (sizes, calibration), with a one-line error.
    warnings.simplefilter("ignore", EmptyResultWarning)
    seg = getattr(args, "segmentation", None)
    motion = getattr(args, "motion", "auto")
    cal_source = str(Path(args.calibration).resolve()) if args.calibration else None
    if cal is not None and cal_source is None:
        cal_source = str((dump.folder / dump.meta["calibration"]).resolve())
    outputs = {"depth_scale": args.depth_scale, "calibration_source": cal_source}
    _init(str(dump.folder), dump.scheme, meta, cal, rng, seg, motion, outputs)
    if _STATE["decoder"].depth_range_problem is not None:
        print(f"slscan decode: warning: {_STATE['decoder'].depth_range_problem}", file=sys.stderr)
    # no more processes than the sets left to decode (each costs ~80 MB and a decoder's set-up), nor than
    # MAX_WORKERS_PER_CORE per core: more only queue for the same cores
    cores = os.cpu_count() or 1
    workers = min(args.workers or cores, MAX_WORKERS_PER_CORE * cores, max(1, len(sets) - 1))
    empty = 0
    with atomic_directory(args.out) as tmp:
        if cal is not None:
            cal.save(Path(tmp) / CALIBRATION_COPY)  # (the sidecars name it: paths in a file stay beside it)
        jobs = [(n, s, str(tmp), args.png16, args.preview) for n, s in enumerate(sets)]
        first = _work(jobs[0])
        empty += first[1] == 0
        done = 1
        _progress(done, len(jobs))
        if len(jobs) > 1:
            if workers > 1:
                with ProcessPoolExecutor(
                    workers,
                    initializer=_init,
                    initargs=(str(dump.folder), dump.scheme, meta, cal, rng, seg, motion, outputs),
                ) as ex:
                    for _, nvalid in ex.map(_work, jobs[1:], chunksize=2):
                        empty += nvalid == 0
                        done += 1
                        _progress(done, len(jobs))
            else:
                for job in jobs[1:]:
                    empty += _work(job)[1] == 0
                    done += 1
                    _progress(done, len(jobs))
    if sys.stderr.isatty():
        print(file=sys.stderr)
    if empty:
        print(
            f"slscan decode: warning: {empty} frame set(s) decoded to an empty depth map "
            f"({_STATE['decoder'].empty_reason()})",
            file=sys.stderr,
        )
    skipped = (
        f", {stats.gaps} frame_id gap(s), {stats.bad_tags} bad tag(s) skipped" if stats.gaps or stats.bad_tags else ""
    )
    textured = f", coloured from {stats.textures} texture frame(s)" if stats.textures else ""
    print(f"decoded {len(sets)} {dump.scheme} frame set(s) from {len(tags)} frames to {args.out}{skipped}{textured}")
    return 0


def _progress(done: int, total: int) -> None:
    if total >= 8 and sys.stderr.isatty():
        width = 30
        fill = int(width * done / total)
        print(f"\r[{'#' * fill}{'.' * (width - fill)}] {done}/{total} frame sets", end="", file=sys.stderr, flush=True)
