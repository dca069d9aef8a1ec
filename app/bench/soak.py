"""`slscan bench --soak --minutes M`: the live pipeline, headless, on the virtual rig for M minutes.

A production bench runs for hours; this shows whether one session stays healthy: process memory
(RSS start / end / peak, and its slope over the second half, where warm-up is over), thread count
and open file descriptors start / end (a leak shows as growth), frames in, depth maps out, the
capture loop's dropped / refused counters, and pairing against the rig's truth: every decoded set
is checked against what the virtual camera really saw (`SimCamera.truth`), and the last sets of
the run are checked separately so a drift that only appears late is not averaged away.

By default drops, swaps, duplicates and late flips are injected at random (as `bench --live`'s
pairing run), so the pairing checks are exercised all along; `--soak-clean` runs without faults.
Uses the live session's public API (`build_session`, `LivePipeline`); nothing is copied here.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from collections import deque

from app.argtypes import positive_float, positive_int

FLAG = "--soak"
KEY = "soak"
HELP = "soak: the live pipeline headless on the virtual rig for --minutes M; memory, threads, fds, pairing drift"
DEFAULT = False  # minutes of wall time: only when asked for

FAULTS = [
    {"kind": "drop", "probability": 0.002},
    {"kind": "swap", "probability": 0.002},
    {"kind": "duplicate", "probability": 0.001},
    {"kind": "late_flip", "probability": 0.001},
]
TAIL_SETS = 200  # the last decoded sets, checked apart: "no drift at the end"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--minutes", type=positive_float, default=30.0, metavar="M", help="soak length in minutes (soak)"
    )
    parser.add_argument(
        "--soak-sample", type=positive_float, default=30.0, metavar="S", help="seconds between resource samples (soak)"
    )
    parser.add_argument("--soak-clean", action="store_true", help="no injected faults (soak)")
    parser.add_argument("--soak-workers", type=positive_int, default=1, metavar="W", help="decode threads (soak)")


# ------------------------------------------------------------------------------------ process figures


def _status_kb(field: str) -> int:
    """A field of /proc/self/status in kB (VmRSS, VmHWM) or a count (Threads); 0 where there is no /proc."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def open_fds() -> int:
    try:
        return len(os.listdir("/proc/self/fd")) - 1  # minus the one listdir itself opened
    except OSError:
        return -1


def sample() -> dict:
    """RSS (MB), threads (OS and Python) and open fds of this process, now."""
    return {
        "t_s": 0.0,
        "rss_mb": round(_status_kb("VmRSS") / 1024, 1),
        "threads": _status_kb("Threads"),
        "py_threads": threading.active_count(),
        "fds": open_fds(),
    }


def slope_mb_per_min(samples: list[dict]) -> float:
    """Least-squares RSS slope over the second half of the samples (warm-up excluded)."""
    half = samples[len(samples) // 2 :]
    if len(half) < 2:
        return 0.0
    t = [s["t_s"] / 60 for s in half]
    r = [s["rss_mb"] for s in half]
    tm, rm = sum(t) / len(t), sum(r) / len(r)
    den = sum((x - tm) ** 2 for x in t)
    return sum((x - tm) * (y - rm) for x, y in zip(t, r, strict=True)) / den if den else 0.0


# ------------------------------------------------------------------------------------ the soak


def soak(
    minutes: float,
    *,
    faults: bool = True,
    workers: int = 1,
    sample_s: float = 30.0,
    seed: int = 11,
    sim_overrides: dict | None = None,
) -> dict:
    """Run the live pipeline for `minutes`; returns the figures (see module docstring).

    sim_overrides: extra `sim:` keys of config/sim.yaml (tests run it at 320x240)."""
    from app.live_pipeline import LivePipeline
    from app.session import build_session

    before = sample()  # before the session exists: what the process holds without it
    overrides = {**(sim_overrides or {}), "seed": seed, **({"faults": FAULTS} if faults else {})}
    session = build_session(None, sim_overrides=overrides)
    processor = session.processor()
    cam = session.sim.camera
    lock = threading.Lock()
    counts = {"checked": 0, "mispaired": 0, "unknown": 0}
    tail: deque[bool] = deque(maxlen=TAIL_SETS)

    def check(res) -> None:
        # frames[p] must have seen pattern p, by the rig's own record of what it showed
        truth = [cam.truth(f.frame_id) for f in res.frameset.frames]
        ok = truth == list(range(len(truth)))
        with lock:
            counts["checked"] += 1
            if None in truth and not ok:
                counts["unknown"] += 1  # truth no longer kept (far behind): cannot judge
            elif not ok:
                counts["mispaired"] += 1
            tail.append(ok)

    pipe = LivePipeline(lambda: session.make_loop(timeout_s=3.0), processor, workers=workers, on_result=check)
    t0 = time.monotonic()
    pipe.start()
    start = sample()
    samples = [start]
    peak = start["rss_mb"]
    end_at = t0 + minutes * 60
    try:
        while pipe.running and time.monotonic() < end_at:
            time.sleep(min(1.0, max(0.0, end_at - time.monotonic())))
            s = sample()
            peak = max(peak, s["rss_mb"])
            if time.monotonic() - t0 >= len(samples) * sample_s:
                s["t_s"] = round(time.monotonic() - t0, 1)
                s["frames"] = pipe.capture.frames
                s["depth_maps"] = pipe.stats.decoded
                samples.append(s)
    finally:
        pipe.stop()
        pipe.join(30.0)
    end_running = samples[-1]  # the last sample while the session ran
    elapsed = time.monotonic() - t0
    pipe.latest = pipe.loop = None  # drop the last result before measuring what stays after the session
    after = sample()
    fig = pipe.figures()
    cap = fig["capture"]
    return {
        "minutes": round(elapsed / 60, 2),
        "faults": "drop/swap/duplicate/late_flip injected" if faults else "none",
        "rss_mb_before": before["rss_mb"],
        "rss_mb_start": start["rss_mb"],
        "rss_mb_end": end_running["rss_mb"],
        "rss_mb_peak": round(peak, 1),
        "rss_mb_after": after["rss_mb"],
        "rss_mb_hwm": round(_status_kb("VmHWM") / 1024, 1),  # the kernel's high-water mark, whole process
        "rss_slope_mb_per_min": round(slope_mb_per_min(samples), 3),
        "threads_before": before["threads"],
        "threads_start": start["threads"],
        "threads_end": end_running["threads"],
        "threads_after": after["threads"],
        "fds_before": before["fds"],
        "fds_start": start["fds"],
        "fds_end": end_running["fds"],
        "fds_after": after["fds"],
        "frames_in": fig["frames"],
        "frames_per_s": round(fig["frames"] / elapsed, 1) if elapsed else 0.0,
        "depth_maps_out": fig["depth_maps"],
        "depth_per_s": round(fig["depth_maps"] / elapsed, 1) if elapsed else 0.0,
        "sets_checked": counts["checked"],
        "mispaired": counts["mispaired"],
        "truth_unknown": counts["unknown"],
        "tail_sets": len(tail),
        "tail_mispaired": sum(1 for ok in tail if not ok),
        "dropped": cap["dropped"],
        "duplicates": cap["duplicates"],
        "out_of_order": cap["out_of_order"],
        "mistagged": cap["mistagged"],
        "untracked": cap["untracked"],
        "refused": cap["refused"],
        "resyncs": cap["resyncs"],
        "camera_overrun": cam.dropped,  # the virtual rig's camera: frames lost to a slow consumer
        "stale_sets": fig["stale_sets"],
        "decode_failed": pipe.stats.failed,
        "latency_ms_p95": round(fig["latency_ms_p95"], 1),
        "error": pipe.error or pipe.decode_error or "",
        "samples": samples,
    }


def run(args: argparse.Namespace) -> list[dict]:
    from core.errors import InputError

    minutes, sample_s = getattr(args, "minutes", 30.0), getattr(args, "soak_sample", 30.0)
    if not minutes > 0:
        raise InputError(f"--minutes {minutes}: must be more than 0")
    if not sample_s > 0:
        raise InputError(f"--soak-sample {sample_s}: must be more than 0 seconds")
    if getattr(args, "soak_workers", 1) < 1:
        raise InputError(f"--soak-workers {args.soak_workers}: must be at least 1")
    return [
        soak(
            minutes,
            faults=not getattr(args, "soak_clean", False),
            workers=getattr(args, "soak_workers", 1),
            sample_s=sample_s,
        )
    ]


ROWS = (
    ("minutes", "minutes run"),
    ("faults", "faults"),
    ("rss_mb_before", "RSS MB before session"),
    ("rss_mb_start", "RSS MB start"),
    ("rss_mb_end", "RSS MB end"),
    ("rss_mb_peak", "RSS MB peak"),
    ("rss_mb_hwm", "RSS MB high-water (kernel)"),
    ("rss_mb_after", "RSS MB after stop"),
    ("rss_slope_mb_per_min", "RSS slope, 2nd half (MB/min)"),
    ("threads_start", "threads start"),
    ("threads_end", "threads end"),
    ("threads_after", "threads after stop"),
    ("fds_start", "open fds start"),
    ("fds_end", "open fds end"),
    ("fds_after", "open fds after stop"),
    ("frames_in", "frames in"),
    ("frames_per_s", "frames/s"),
    ("depth_maps_out", "depth maps out"),
    ("depth_per_s", "depth maps/s"),
    ("sets_checked", "sets checked vs truth"),
    ("mispaired", "MISPAIRED"),
    ("tail_mispaired", "MISPAIRED in last sets"),
    ("truth_unknown", "truth unknown"),
    ("dropped", "dropped"),
    ("duplicates", "duplicates"),
    ("out_of_order", "out of order"),
    ("mistagged", "mistagged (late flip)"),
    ("untracked", "untracked"),
    ("resyncs", "resyncs"),
    ("camera_overrun", "camera buffer overrun"),
    ("stale_sets", "stale sets"),
    ("decode_failed", "decode failed"),
    ("latency_ms_p95", "latency p95 ms"),
    ("error", "error"),
)


def format_table(rows: list[dict]) -> str:
    lines = []
    for r in rows:
        w = max(len(h) for _, h in ROWS)
        lines += [f"{h.ljust(w)}  {r.get(k, '')}" for k, h in ROWS]
        samples = r.get("samples", [])
        if samples:
            lines.append("samples (t s: RSS MB / threads / fds / frames / depth maps):")
            lines.append(
                "  "
                + "  ".join(
                    f"{s['t_s']:.0f}: {s['rss_mb']}/{s['threads']}/{s['fds']}/{s.get('frames', 0)}/"
                    f"{s.get('depth_maps', 0)}"
                    for s in samples
                )
            )
    lines.append("healthy: RSS end ~ start (slope ~ 0), threads and fds end = start, 0 mispaired, no error")
    return "\n".join(lines)
