"""`slscan bench --cluster`: `slscan decode --scheduler` throughput on LocalClusters of 1 and 2 workers, side by side
with the same chunks decoded in this process (no scheduler).

A two-shot dump of the face scene is written once (two rendered frames repeated: the decode's work per set is that
of a real pair; the PNGs, TIFFs and PLYs are written as in a run). Every worker first decodes one warm-up chunk, so the
timed part is the steady state: the decoder built, its kernels loaded. Rows:

- in-process: the chunks one after the other through the worker's own task function (app/cluster/task.py), in this
  process: the work without any scheduler.
- local:1, local:2: the same chunks submitted to a LocalCluster of 1 or 2 single-threaded worker processes.

Wall time is what a user waits for, and on a shared machine it moves with the other load (the 1-minute load
average is in each row). CPU ms a set is the decoding thread's CPU time (`time.thread_time`) per set, per worker:
it does not grow with other load, and it stays flat from 1 to 2 workers when the work scales. busy is the share of
the workers' wall time spent inside tasks (1 - busy is what scheduling and waiting cost); CPU the share of their wall
time the workers got a core (below 100 % where other load took it). "by CPU a set" is the ratio local:2 would reach on
two idle cores: 2 x local:1's CPU a set / local:2's. Targets: local:2 at least
1.8x the sets/s of local:1; the scheduler's overhead at chunks of 60 sets (local:1's time outside tasks, 1 - busy)
at most 5 %. local:1's wall against in-process is shown too: on a quiet machine it is the same figure; on a shared
one it also carries the other load's swings between the two timings.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from app.argtypes import positive_int
from core.patterns import parse_size

FLAG = "--cluster"
KEY = "cluster"
HELP = "decode --scheduler throughput: in-process vs LocalCluster of 1 and 2 workers (needs slscan[cluster])"
DEFAULT = False  # half a minute to minutes, and an extra: only when asked for

TARGET_RATIO = 1.8  # local:2 / local:1 sets/s
TARGET_OVERHEAD = 0.05  # local:1: 1 - busy


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--cluster-sets", type=positive_int, default=240, metavar="N", help="frame sets to decode (cluster)"
    )
    parser.add_argument(
        "--cluster-chunk-sets", type=positive_int, default=60, metavar="N", help="frame sets per task (cluster)"
    )
    parser.add_argument(
        "--cluster-size", default="640x480", metavar="WxH", help="camera size of the bench's dump (cluster)"
    )


def _write_dump(folder: Path, n_sets: int, size: tuple[int, int]) -> None:
    from app.patterns import two_shot_patterns
    from core.dump import DumpWriter
    from drivers.sim.rig import VirtualRig

    rig = VirtualRig.from_preset("face", camera_size=size)
    ps = two_shot_patterns(rig.projector_size)
    images = [rig.render(ps.images[p]) for p in (0, 1)]
    with DumpWriter(folder, ps, rig.calibration, rig.depth_range_mm) as w:
        for i in range(n_sets + 1):
            p = i % 2
            w.add(images[p], p, i, 16_666_667 * i)


def run(args: argparse.Namespace) -> list[dict]:
    from app.cluster.chunks import make_chunks
    from app.cluster.client import open_client, require_distributed
    from app.cluster.manifest import create_out
    from app.cluster.task import decode_chunk
    from app.offline_decode import plan_dump

    distributed = require_distributed()
    w, h = parse_size(args.cluster_size)  # (a malformed size is an InputError naming it)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="slscan-bench-cluster-") as tmp:
        root = Path(tmp)
        _write_dump(root / "dump", args.cluster_sets, (w, h))
        plan = plan_dump(root / "dump")
        chunks = make_chunks(plan.sets, args.cluster_chunk_sets)
        warm = make_chunks(plan.sets[:3], 3)[0]  # (sets with a previous frame too: every kernel loaded)

        def fresh_out(name: str) -> Path:
            out = root / name
            shutil.rmtree(out, ignore_errors=True)
            create_out(out, {}, ["."], resumed=True)  # (the folders a task writes into; no manifest needed here)
            return out

        # in-process: the task function itself, chunk after chunk
        out = fresh_out("warm")
        decode_chunk("bench", plan.settings, warm, str(out), ".")
        out = fresh_out("in-process")
        load0, t0 = os.getloadavg()[0], time.perf_counter()
        results = [decode_chunk("bench", plan.settings, c, str(out), ".") for c in chunks]
        rows.append(_row("in-process", 1, results, time.perf_counter() - t0, load0, args))
        for n in (1, 2):
            with open_client(f"local:{n}") as client:
                addresses = list(client.scheduler_info()["workers"])
                warm_out = fresh_out("warm")
                distributed.wait(
                    [
                        client.submit(
                            decode_chunk, "bench", plan.settings, warm, str(warm_out), ".", workers=[a], pure=False
                        )
                        for a in addresses
                    ]
                )
                out = fresh_out(f"local-{n}")
                load0, t0 = os.getloadavg()[0], time.perf_counter()
                futures = [
                    client.submit(decode_chunk, "bench", plan.settings, c, str(out), ".", pure=False) for c in chunks
                ]
                results = client.gather(futures)
                rows.append(_row(f"local:{n}", n, results, time.perf_counter() - t0, load0, args))
    by = {r["mode"]: r for r in rows}
    by["local:1"]["overhead_vs_in_process"] = round(by["local:1"]["wall_s"] / by["in-process"]["wall_s"] - 1, 4)
    # the scheduler's cost is the worker's time outside tasks; the wall comparison also carries the other load's swings
    by["local:1"]["scheduler_overhead"] = round(1 - by["local:1"]["busy"], 4)
    by["local:1"]["target_met"] = by["local:1"]["scheduler_overhead"] <= TARGET_OVERHEAD
    by["local:2"]["ratio_vs_local_1"] = round(by["local:2"]["sets_per_s"] / by["local:1"]["sets_per_s"], 3)
    by["local:2"]["target_met"] = by["local:2"]["ratio_vs_local_1"] >= TARGET_RATIO
    # what the ratio would be on two idle cores: the workers' CPU a set, which other load does not inflate
    one, two = by["local:1"]["cpu_ms_per_set"], by["local:2"]["cpu_ms_per_set"]
    by["local:2"]["idle_cores_ratio"] = round(2 * (sum(one) / len(one)) / (sum(two) / len(two)), 3)
    return rows


def _row(mode: str, workers: int, results: list, wall: float, load0: float, args: argparse.Namespace) -> dict:
    from app.cluster.summary import per_worker

    figures = per_worker(results)
    sets = sum(r.sets for r in results)
    return {
        "mode": mode,
        "workers": workers,
        "size": args.cluster_size,
        "sets": sets,
        "chunk_sets": args.cluster_chunk_sets,
        "wall_s": round(wall, 3),
        "sets_per_s": round(sets / wall, 2),
        "cpu_ms_per_set": [round(f.cpu_ms_per_set, 2) for f in figures],
        "sets_by_worker": [f.sets for f in figures],
        "busy": round(sum(f.busy_s for f in figures) / (workers * wall), 3),
        # the CPU the workers got of their wall time: below 1 where other load took the cores
        "cpu_share": round(sum(f.cpu_s for f in figures) / (workers * wall), 3),
        "loadavg_1min": [round(load0, 2), round(os.getloadavg()[0], 2)],  # at the start and the end of the timing
    }


def format_table(rows: list[dict]) -> str:
    head = f"{'mode':<11} {'sets':>5} {'chunk':>5} {'wall s':>7} {'sets/s':>7} {'CPU ms a set, per worker':>25} "
    head += f"{'busy':>5} {'CPU':>5} {'load avg':>11}  vs"
    lines = [head]
    for r in rows:
        cpu = " / ".join(f"{v:.1f}" for v in r["cpu_ms_per_set"])
        vs = ""
        if "overhead_vs_in_process" in r:
            vs = f"outside tasks {100 * r['scheduler_overhead']:.1f} % (target <= 5 %), "
            vs += f"{100 * r['overhead_vs_in_process']:+.1f} % wall vs in-process"
        if "ratio_vs_local_1" in r:
            vs = f"{r['ratio_vs_local_1']:.2f}x local:1 (target >= {TARGET_RATIO}x)"
            vs += f", by CPU a set {r['idle_cores_ratio']:.2f}x"
        load = "-".join(f"{v:.1f}" for v in r["loadavg_1min"])
        lines.append(
            f"{r['mode']:<11} {r['sets']:>5} {r['chunk_sets']:>5} {r['wall_s']:>7.2f} {r['sets_per_s']:>7.2f} "
            f"{cpu:>25} {100 * r['busy']:>4.0f}% {100 * r['cpu_share']:>4.0f}% {load:>11}  {vs}"
        )
    return "\n".join(lines)
