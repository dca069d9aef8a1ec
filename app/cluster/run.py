"""`slscan decode DUMP... --out OUT --scheduler ADDRESS`: the run on a Dask cluster, from the checks to the summary.

Order of events (each step before the next): the dumps are read and checked and OUT is checked (nothing written);
the scheduler is reached (a silent one ends the run, nothing written); OUT gets its manifest; the chunks complete
from an earlier run are skipped and the rest submitted; the summary is printed. Exit status 0 when every set is
decoded, 1 when chunks failed (a rerun retries them), 2 for bad input.
"""

from __future__ import annotations

import argparse
import hashlib
import pickle
import sys
import time
import uuid
from pathlib import Path

from app.cluster.chunks import DEFAULT_CHUNK_SETS, make_chunks
from app.cluster.client import DEFAULT_CONNECT_TIMEOUT_S, open_client, parse_address, require_distributed
from app.cluster.manifest import (
    check_out,
    chunk_complete,
    create_out,
    index_digest,
    remove_partials,
    run_manifest,
)
from app.cluster.summary import Failure, RunSummary
from app.cluster.task import ChunkResult, decode_chunk
from app.cluster.zarr_depth import create_store, require_zarr
from app.offline_decode import DumpPlan, output_subfolders, plan_dumps, write_calibration_copy
from core.errors import InputError


def run_on_cluster(args: argparse.Namespace) -> int:
    distributed = require_distributed()
    parse_address(args.scheduler)  # (a malformed address is refused before any dump is read)
    plans = plan_dumps(args, resolve=True)
    subs = output_subfolders([p.dump.folder for p in plans])
    shapes = [_check_first_frame(plan) for plan in plans]
    if args.zarr:
        require_zarr()
        for plan in plans:
            if plan.settings.calibration is None:
                raise InputError(f"{plan.dump.folder}: --zarr writes depth maps, which need a calibration")
    size = args.chunk_sets or DEFAULT_CHUNK_SETS
    chunks = [make_chunks(p.sets, size, d) for d, p in enumerate(plans)]
    manifest = run_manifest(
        [
            {
                "folder": str(p.dump.folder),
                "index_sha256": index_digest(p.dump.folder),
                "subfolder": sub,
                "sets": len(p.sets),
                "chunks": len(c),
            }
            for p, sub, c in zip(plans, subs, chunks, strict=True)
        ],
        {
            "chunk_sets": size,
            "calibration_sha256": [p.calibration_digest for p in plans],
            "disjoint": bool(args.disjoint),
            "segmentation": getattr(args, "segmentation", None),
            "motion": getattr(args, "motion", "auto"),
            "png16": bool(args.png16),
            "preview": bool(args.preview),
            "depth_scale": float(args.depth_scale),
            "zarr": bool(args.zarr),
        },
    )
    out = Path(args.out).absolute()
    resumed = check_out(out, manifest)
    summary = RunSummary()
    t0 = time.perf_counter()
    with open_client(args.scheduler, args.connect_timeout or DEFAULT_CONNECT_TIMEOUT_S) as client:
        create_out(out, manifest, subs, resumed)
        for plan, sub in zip(plans, subs, strict=True):
            write_calibration_copy(plan, out / sub)
        if args.zarr:
            for plan, sub, shape in zip(plans, subs, shapes, strict=True):
                create_store(out / sub, plan.dump, plan.sets, shape, size)
        summary.partials_removed = remove_partials(out)  # an earlier run's killed attempts (no task is running)
        token = uuid.uuid4().hex[:12]
        futures = {}
        for d, (plan, sub) in enumerate(zip(plans, subs, strict=True)):
            key = _decoder_key(plan)
            for chunk in chunks[d]:
                if resumed and chunk_complete(out, sub, chunk):
                    summary.skipped_chunks += 1
                    summary.skipped_sets += len(chunk.sets)
                    continue
                f = client.submit(
                    decode_chunk,
                    key,
                    plan.settings,
                    chunk,
                    str(out),
                    sub,
                    bool(args.zarr),
                    key=f"slscan-decode-{token}-d{d}-c{chunk.number:06d}",
                    pure=False,
                )
                futures[f] = (plan, chunk)
        bar = _Progress(client, len(futures), sum(len(c.sets) for _, c in futures.values()))
        for f in distributed.as_completed(list(futures)):
            plan, chunk = futures[f]
            if f.status == "finished":
                summary.results.append(f.result())
            else:
                summary.failures.append(Failure(str(plan.dump.folder), chunk, _reason(f.exception())))
            bar.update(summary)
            f.release()
        bar.close()
        summary.partials_removed += remove_partials(out)  # this run's killed attempts (all tasks are done)
    summary.wall_s = time.perf_counter() - t0
    _warnings(summary.results)
    for d, (plan, sub) in enumerate(zip(plans, subs, strict=True)):
        _dump_line(plan, args.out if sub == "." else str(Path(args.out) / sub), summary, d)
    for line in summary.lines(args.out):
        print(line)
    return 1 if summary.failures else 0


def _decoder_key(plan: DumpPlan) -> str:
    """What a worker keeps its decoder (and the dump index it read) under: the digest of the settings and of the
    dump's index, so a long-lived cluster's workers reuse it across runs of the same dump and options, and never
    across a dump that changed."""
    settings = hashlib.sha256(pickle.dumps(plan.settings)).hexdigest()
    return hashlib.sha256(f"{settings}:{index_digest(plan.dump.folder)}".encode()).hexdigest()[:16]


def _check_first_frame(plan: DumpPlan) -> tuple[int, int]:
    """The first set's frame size (H, W), checked against the calibration here, in one line, before any task runs."""
    cal = plan.settings.calibration
    i = plan.sets[0].indices[0]
    frame = plan.dump.load_frame(i)
    if cal is not None:
        cal.check_camera_size(frame.shape[1], frame.shape[0], str(plan.dump.folder / plan.dump.frames[i].file))
    return frame.shape[0], frame.shape[1]


def _reason(exc: BaseException | None) -> str:
    if exc is None:
        return "cancelled"
    if type(exc).__name__ == "KilledWorker":  # the scheduler's allowed-failures: every worker that ran it died
        return "every worker that took it died (killed, or out of memory)"
    return f"{type(exc).__name__}: {exc}" if not str(exc).startswith("/") else str(exc)


def _warnings(results: list[ChunkResult]) -> None:
    problem = next((r.depth_range_problem for r in results if r.depth_range_problem), None)
    if problem is not None:
        print(f"slscan decode: warning: {problem}", file=sys.stderr)
    slow = sorted({r.worker for r in results if r.malloc_trim is not None})
    if slow:
        print(
            f"slscan decode: warning: {len(slow)} worker(s) run with MALLOC_TRIM_THRESHOLD_ set (Dask's nanny "
            "default), which costs +50-80 % CPU a set: unset it in the workers' Dask config (README, \"Decoding on a "
            'cluster")',
            file=sys.stderr,
        )
    empty = sum(r.empty for r in results)
    if empty:
        reason = next(r.empty_reason for r in results if r.empty)
        print(f"slscan decode: warning: {empty} frame set(s) decoded to an empty depth map ({reason})", file=sys.stderr)


def _dump_line(plan: DumpPlan, shown: str, summary: RunSummary, d: int) -> None:
    decoded = sum(r.sets for r in summary.results if r.dump == d)
    stats = plan.stats
    gaps = ""
    if stats.gaps or stats.bad_tags:
        gaps = f", {stats.gaps} frame_id gap(s), {stats.bad_tags} bad tag(s) skipped"
    print(
        f"decoded {decoded} of {len(plan.sets)} {plan.dump.scheme} frame set(s) from {plan.n_frames} frames to "
        f"{shown}{gaps}"
    )


class _Progress:
    """A bar on stderr (a terminal only): chunks done of those submitted, and the scheduler's count of the tasks
    processing on workers now."""

    def __init__(self, client: object, chunks: int, sets: int) -> None:
        self.client, self.chunks, self.sets = client, chunks, sets
        self.live = sys.stderr.isatty() and chunks > 0

    def update(self, s: RunSummary) -> None:
        if not self.live:
            return
        done = len(s.results) + len(s.failures)
        running = sum(len(v) for v in self.client.processing().values())
        width = 30
        fill = int(width * done / self.chunks)
        print(
            f"\r[{'#' * fill}{'.' * (width - fill)}] chunks {done}/{self.chunks} ({running} running, "
            f"{len(s.failures)} failed), sets {s.decoded_sets}/{self.sets}",
            end="",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        if self.live:
            print(file=sys.stderr)
