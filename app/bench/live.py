"""`slscan bench --live`: the live session on the virtual rig at 640x480 (targets in docs/performance.md).

Three measurements, each a table row:
- live: the whole pipeline (trigger-paced capture, decode worker(s), no view) for N frames, with the
  3-CCD-like virtual camera and with a single-chip RGGB one (raw frames, app/decode/mosaic.py):
  frames/s in, depth maps/s out, p50/p95 latency (host arrival of a set's newest frame -> depth
  ready), per-stage medians, dropped / refused / stale counts. Targets: 60 in, >= 55 out, p95 <= 50 ms.
- pairing: the capture loop alone (no decode) over M frames with drops, duplicates, swaps and
  late flips injected at random; every set is checked against what the virtual camera really
  showed (its ground truth). Target: 0 mispaired.
- record: the capture loop feeding the recorder (PNG level 0 and 1, and a single-chip RGGB camera's raw
  frames at level 1) for N frames. Target: every tagged frame written, none lost.
- published: the live row's session publishing every scan (--publish, app/publisher.py) to a subscriber in
  another process on loopback: scans received of those made, sequence gaps, and the latency added (depth ready ->
  the subscriber has the arrays). Targets: every scan received at 60 Hz, p50 latency <= 2 ms.
- view images: the operator view's image work per shown result at 640x480 (stripe and depth
  panels, the 3D point view), without a window. Target for the point view: well under 2 ms.
The live row's notes give the CPU each thread used per camera frame: where the time outside
decode + triangulate goes (the acquisition thread includes the virtual camera's rendering).
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import numpy as np

from app.argtypes import positive_int
from app.live_pipeline import DECODE_WORKERS, WORKERS_HELP

FLAG = "--live"
KEY = "live"
HELP = "live session on the virtual rig: frames/s in, depth maps/s out, latency, mispaired, recording"
DEFAULT = False  # minutes of real-time capture: only when asked for

FAULTS = [
    {"kind": "drop", "probability": 0.01},
    {"kind": "swap", "probability": 0.01},
    {"kind": "duplicate", "probability": 0.005},
    {"kind": "late_flip", "probability": 0.005},
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--live-frames", type=positive_int, default=600, metavar="N", help="frames per live/record run (live)"
    )
    parser.add_argument(
        "--live-pairing-frames",
        type=positive_int,
        default=10_000,
        metavar="M",
        help="frames with injected faults (live)",
    )
    parser.add_argument("--live-workers", type=positive_int, default=DECODE_WORKERS, metavar="W", help=WORKERS_HELP)


def _live_row(frames: int, workers: int, bayer: str | None = None) -> dict:
    from app.live_pipeline import LivePipeline
    from app.session import build_session

    session = build_session(None, sim_overrides={"bayer": bayer} if bayer else None)
    processor = session.processor()
    cam = session.sim.camera
    mispaired = 0

    def check(res) -> None:
        nonlocal mispaired
        ids = res.frameset.frame_ids
        if [cam.truth(i) for i in ids] != list(range(len(ids))):
            mispaired += 1

    pipe = LivePipeline(
        lambda: session.make_loop(timeout_s=3.0), processor, workers=workers, max_frames=frames, on_result=check
    )
    pipe.start()
    pipe.wait()
    fig = pipe.figures()
    cpu = ", ".join(f"{k} {v:.2f}" for k, v in fig["cpu_ms_per_frame"].items())
    return {
        "run": f"live{f' raw {bayer}' if bayer else ''}, {workers} decode thread(s)",
        "frames": fig["frames"],
        "frames_per_s": round(fig["frames_per_s"], 1),
        "depth_maps_per_s": round(fig["depth_per_s"], 1),
        "latency_p50_ms": round(fig["latency_ms_p50"], 1),
        "latency_p95_ms": round(fig["latency_ms_p95"], 1),
        "decode_ms": round(fig["decode_ms_p50"], 1),
        "triangulate_ms": round(fig["triangulate_ms_p50"], 1),
        "dropped": fig["dropped"],
        "refused": fig["refused"],
        "mispaired": mispaired,
        "stale_sets": fig["stale_sets"],
        "lost": 0,
        "error": (pipe.error + "; " if pipe.error else "")
        + f"CPU ms per frame by thread: {cpu} (acquisition includes the virtual camera's rendering)",
    }


def _published_row(frames: int, workers: int) -> dict:
    """The live session with a subscriber process receiving its stream (app/bench/stream_receiver.py)."""
    import json
    import os
    import socket
    import subprocess
    import sys
    from pathlib import Path

    from app.live_pipeline import LivePipeline
    from app.publisher import DepthPublisher
    from app.session import build_session

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    publisher = DepthPublisher(address)
    root = str(Path(__file__).resolve().parents[2])  # the folder holding app/ and core/
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    receiver = subprocess.Popen(
        [sys.executable, "-m", "app.bench.stream_receiver", address], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        assert receiver.stdout is not None
        receiver.stdout.readline()  # "ready": connected
        session = build_session(None)
        processor = session.processor()
        publisher.attach(processor)
        pipe = LivePipeline(
            lambda: session.make_loop(timeout_s=3.0),
            processor,
            workers=workers,
            max_frames=frames,
            on_result=publisher.offer,
        )
        pipe.start()
        pipe.wait()
    finally:
        publisher.close()
    out, _ = receiver.communicate(timeout=60)
    got = json.loads(out.splitlines()[-1]) if out.strip() else {"received": 0, "missed": 0, "ended": False}
    fig = pipe.figures()
    return {
        "run": "published (subscriber process)",
        "frames": fig["frames"],
        "frames_per_s": round(fig["frames_per_s"], 1),
        "depth_maps_per_s": round(fig["depth_per_s"], 1),
        "latency_p50_ms": round(got.get("latency_p50_ms", float("nan")), 2),
        "latency_p95_ms": round(got.get("latency_p95_ms", float("nan")), 2),
        "dropped": fig["dropped"],
        "lost": fig["depth_maps"] - got["received"],
        "error": f"received {got['received']} of {fig['depth_maps']} scans, {got['missed']} sequence gap(s), "
        f"{publisher.dropped} dropped by the publisher ({publisher.stale} older than one sent); "
        "latency = depth ready -> arrays in the subscriber"
        + ("" if got["ended"] else "; the end message did not arrive"),
    }


def _view_row(repeats: int = 30) -> dict:
    """The operator view's image work per shown result at 640x480, without a window (pure functions)."""
    from app.live_pipeline import LivePipeline
    from app.session import build_session
    from app.view import PointPanel, depth_panel, stripe_panel

    session = build_session(None)
    processor = session.processor()
    pipe = LivePipeline(lambda: session.make_loop(timeout_s=3.0), processor, max_frames=20)
    pipe.start()
    pipe.wait()
    res = pipe.latest
    if res is None:
        return {"run": "view images", "error": pipe.error or pipe.decode_error or "no depth map"}
    tri = processor.triangulator
    panel = PointPanel(tri.ray, session.calibration.camera_matrix, tri.depth_range_mm)
    panel.turn(20.0, 10.0)

    def median_ms(fn) -> float:
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            times.append((time.perf_counter() - t0) * 1e3)
        return float(np.median(times))

    stripes = median_ms(lambda: stripe_panel(res.stripes))
    depth = median_ms(lambda: depth_panel(res.depth, tri.depth_range_mm))
    points = median_ms(lambda: panel.render(res))
    n_points = int((res.depth[:: panel.step, :: panel.step] > 0).sum())
    return {
        "run": "view images, 640x480",
        "frames": "",
        "error": f"per result: stripes {stripes:.2f} ms, depth {depth:.2f} ms, 3D points {points:.2f} ms "
        f"({n_points} points, every {panel.step}th pixel, {panel.size[0]}x{panel.size[1]} render); "
        f"total {stripes + depth + points:.2f} ms",
    }


def _pairing_row(frames: int) -> dict:
    from app.session import build_session

    session = build_session(None, sim_overrides={"faults": FAULTS, "seed": 7})
    cam = session.sim.camera
    loop = session.make_loop(timeout_s=3.0)
    sets = mispaired = 0
    t0 = time.monotonic()
    try:
        loop.start()
        for _ in range(frames):
            ev = loop.step()
            if ev.frameset is not None:
                sets += 1
                ids = ev.frameset.frame_ids
                truth = [cam.truth(i) for i in ids]
                if truth != list(range(len(ids))) or sorted(ids) != list(range(min(ids), min(ids) + len(ids))):
                    mispaired += 1
    finally:
        loop.close()
    elapsed = time.monotonic() - t0
    st = loop.stats
    return {
        "run": "pairing, faults injected",
        "frames": st.frames,
        "frames_per_s": round(st.frames / elapsed, 1),
        "depth_maps_per_s": "",
        "latency_p50_ms": "",
        "latency_p95_ms": "",
        "decode_ms": "",
        "triangulate_ms": "",
        "dropped": st.dropped,
        "refused": st.refused,
        "mispaired": mispaired,
        "stale_sets": "",
        "lost": 0,
        "error": f"{sets} sets; dup {st.duplicates}, swap {st.out_of_order}, late {st.mistagged}, "
        f"untracked {st.untracked}",
    }


def _record_row(frames: int, png_level: int, bayer: str | None = None) -> dict:
    import tempfile
    from pathlib import Path

    from app.live_pipeline import LivePipeline
    from app.session import build_session, open_recorder
    from core.dump import read_dump

    session = build_session(None, sim_overrides={"bayer": bayer} if bayer else None)
    with tempfile.TemporaryDirectory(prefix="slscan-bench-rec-") as tmp:
        rec = open_recorder(session, Path(tmp) / "rec", png_level)
        pipe = LivePipeline(lambda: session.make_loop(timeout_s=3.0), None, max_frames=frames, recorder=rec)
        pipe.start()
        pipe.wait()
        stats = rec.close()
        on_disk = len(read_dump(Path(tmp) / "rec").frames)
        size_mb = sum(p.stat().st_size for p in (Path(tmp) / "rec" / "frames").glob("*.png")) / 1e6
    w = np.asarray(stats.write_ms) if stats.write_ms else np.array([np.nan])
    fig = pipe.figures()
    return {
        "run": f"record{f' raw {bayer}' if bayer else ''}, PNG level {png_level}",
        "frames": fig["frames"],
        "frames_per_s": round(fig["frames_per_s"], 1),
        "depth_maps_per_s": "",
        "latency_p50_ms": "",
        "latency_p95_ms": "",
        "decode_ms": "",
        "triangulate_ms": "",
        "dropped": fig["dropped"],
        "refused": fig["refused"],
        "mispaired": "",
        "stale_sets": "",
        "lost": stats.lost + (pipe.capture.confirmed - on_disk if not stats.lost else 0),
        "error": f"{on_disk} written of {pipe.capture.confirmed} confirmed ({pipe.capture.tagged} tagged); "
        f"write p50 {np.median(w):.1f} ms, "
        f"p95 {np.percentile(w, 95):.1f} ms; {size_mb / max(on_disk, 1):.2f} MB/frame"
        + (f"; {rec.message}" if rec.message else ""),
    }


def run(args: argparse.Namespace) -> list[dict]:
    frames = getattr(args, "live_frames", 600)
    workers = getattr(args, "live_workers", 1)
    rows = [_live_row(frames, workers), _live_row(frames, workers, bayer="RGGB")]
    if importlib.util.find_spec("zmq") is not None:  # (slscan[stream])
        rows.append(_published_row(frames, workers))
    rows.append(_view_row())
    rows.append(_pairing_row(getattr(args, "live_pairing_frames", 10_000)))
    for level in (0, 1):
        rows.append(_record_row(frames, level))
    rows.append(_record_row(frames, 1, bayer="RGGB"))  # one channel: a third of the bytes to compress
    return rows


COLUMNS = (
    ("run", "run"),
    ("frames", "frames"),
    ("frames_per_s", "in/s"),
    ("depth_maps_per_s", "depth/s"),
    ("latency_p50_ms", "lat p50"),
    ("latency_p95_ms", "lat p95"),
    ("decode_ms", "decode"),
    ("triangulate_ms", "triang"),
    ("dropped", "dropped"),
    ("refused", "refused"),
    ("mispaired", "MISPAIRED"),
    ("stale_sets", "stale"),
    ("lost", "LOST"),
    ("error", "notes"),
)


def format_table(rows: list[dict]) -> str:
    widths = {k: max(len(h), *(len(str(r.get(k, ""))) for r in rows)) for k, h in COLUMNS}
    lines = ["  ".join(h.ljust(widths[k]) for k, h in COLUMNS)]
    for r in rows:
        lines.append("  ".join(str(r.get(k, "")).ljust(widths[k]) for k, _ in COLUMNS))
    lines.append(
        "targets (640x480, 2 cores): 60 frames/s in, >= 55 depth maps/s, p95 latency <= 50 ms, "
        "0 mispaired, 0 lost while recording"
    )
    return "\n".join(lines)
