"""`slscan decode DUMP --out OUT`: decode every complete frame set of a dump to depth, cloud and stripes."""

from __future__ import annotations

import argparse
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from app.argtypes import non_negative_int, positive_float, positive_int
from app.export import DEPTH_PNG_SCALE
from app.framesets import FrameIndexSet
from app.fsutil import atomic_directory
from app.offline_decode import (
    DecodeSettings,
    DumpPlan,
    SetDecoder,
    output_subfolders,
    plan_dumps,
    quiet_opencv,
    write_calibration_copy,
)
from core.errors import InputError

HELP = "decode a frame dump offline: depth TIFF, PLY cloud and stripe PNG per frame set"

EPILOG = """\
examples:
  slscan decode rec/ --out out/                     # calibration and depth range from the dump
  slscan decode rec/ --out out/ --calibration cal.yaml --workers 2 --png16 --preview

Frame sets come from the frames' pattern tags: a two-shot set is two frames with consecutive
frame_id tagged {0, 1} in either order (pairs slide: 1-2, 2-3, ...); a gap or a wrong tag is never
decoded. Without a calibration only the stripe PNGs are written.

With --scheduler the sets are decoded in chunks on a Dask cluster; every worker reads its frames
from the dump folder itself (shared storage) and writes each file whole under its final name. OUT
gets a manifest (decode-run.yaml): a rerun of the same command on the same OUT skips the chunks
already complete and decodes the rest; an OUT holding another run, or anything else, is refused.
Exit status 1 when chunks failed (the summary says why; a rerun retries them).
  slscan decode rec1/ rec2/ --out out/ --scheduler tcp://head:8786    # out/rec1/, out/rec2/
  slscan decode rec/ --out out/ --scheduler local:2                    # a LocalCluster of 2 processes
"""

_STATE: dict = {}


MAX_WORKERS_PER_CORE = 2


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "decode", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "dump", metavar="DUMP", nargs="+", help="frame dump folder(s) (slscan-dump v1); several: OUT/<name>/ each"
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="OUT",
        help="output folder (must not exist or be empty; with --scheduler it may hold an earlier run to resume)",
    )
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
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="decode on a Dask cluster: tcp://host:8786, or local[:N] for N worker processes here "
        "(needs slscan[cluster]; resumable: see below)",
    )
    p.add_argument(
        "--chunk-sets", type=positive_int, metavar="N", help="with --scheduler: frame sets per task (default 60)"
    )
    p.add_argument(
        "--connect-timeout",
        type=positive_float,
        metavar="S",
        help="with --scheduler: seconds to wait for the scheduler to answer (default 10)",
    )
    p.add_argument(
        "--zarr",
        action="store_true",
        help="with --scheduler: also every depth map in one chunked Zarr array, OUT[/<name>]/depth.zarr (xarray, dask)",
    )
    p.set_defaults(func=run)


def _init(settings: DecodeSettings) -> None:
    _STATE["worker"] = SetDecoder(settings)


def _work(job: tuple[int, FrameIndexSet, str]) -> tuple[int, int]:
    n, fs, out = job
    return n, _STATE["worker"].decode_set(n, fs, Path(out))


def run(args: argparse.Namespace) -> int:
    quiet_opencv()
    if args.scheduler is None and (args.chunk_sets is not None or args.connect_timeout is not None or args.zarr):
        raise InputError("--chunk-sets, --connect-timeout and --zarr go with --scheduler")
    if args.scheduler is not None:
        from app.cluster.run import run_on_cluster  # (imports dask.distributed: only when asked for)

        return run_on_cluster(args)
    plans = plan_dumps(args)
    subfolders = output_subfolders([p.dump.folder for p in plans])
    with atomic_directory(args.out) as tmp:
        for plan, sub in zip(plans, subfolders, strict=True):
            (tmp / sub).mkdir(exist_ok=True)
            write_calibration_copy(plan, tmp / sub)
            _decode_locally(plan, tmp / sub, args.workers, args.out if sub == "." else str(Path(args.out) / sub))
    return 0


def _decode_locally(plan: DumpPlan, tmp: Path, workers_asked: int, shown: str) -> None:
    """Decode one dump's sets into tmp (the atomic folder that becomes final), on a local process pool."""
    sets = plan.sets
    # Fail early, in this process, on the first set (sizes, calibration), with a one-line error.
    _init(plan.settings)
    decoder = _STATE["worker"].decoder
    if decoder.depth_range_problem is not None:
        print(f"slscan decode: warning: {decoder.depth_range_problem}", file=sys.stderr)
    # no more processes than the sets left to decode (each costs ~80 MB and a decoder's set-up), nor than
    # MAX_WORKERS_PER_CORE per core: more only queue for the same cores
    cores = os.cpu_count() or 1
    workers = min(workers_asked or cores, MAX_WORKERS_PER_CORE * cores, max(1, len(sets) - 1))
    empty = 0
    jobs = [(n, s, str(tmp)) for n, s in enumerate(sets)]
    first = _work(jobs[0])
    empty += first[1] == 0
    done = 1
    _progress(done, len(jobs))
    if len(jobs) > 1:
        if workers > 1:
            with ProcessPoolExecutor(workers, initializer=_init, initargs=(plan.settings,)) as ex:
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
            f"slscan decode: warning: {empty} frame set(s) decoded to an empty depth map ({decoder.empty_reason()})",
            file=sys.stderr,
        )
    stats = plan.stats
    skipped = (
        f", {stats.gaps} frame_id gap(s), {stats.bad_tags} bad tag(s) skipped" if stats.gaps or stats.bad_tags else ""
    )
    textured = f", coloured from {stats.textures} texture frame(s)" if stats.textures else ""
    print(
        f"decoded {len(sets)} {plan.dump.scheme} frame set(s) from {plan.n_frames} frames to {shown}{skipped}{textured}"
    )


def _progress(done: int, total: int) -> None:
    if total >= 8 and sys.stderr.isatty():
        width = 30
        fill = int(width * done / total)
        print(f"\r[{'#' * fill}{'.' * (width - fill)}] {done}/{total} frame sets", end="", file=sys.stderr, flush=True)
