"""`slscan bench --render`: the virtual rig's per-frame render time (the live session needs < 16 ms).

Still rows: the scene of --render-scene at 640x480 and 1280x1024, after the per-scene precomputation.
Moving rows (640x480, the live session's size): every frame moves the scene's moving objects, so
each render includes that frame's ray casts and shading (drivers/sim/moving.py); `precompute s` is
the rig's construction (the static layer and frame 0). Target for moving scenes: <= 30 ms a frame.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from app.argtypes import positive_int

FLAG = "--render"
KEY = "render"
HELP = (
    "virtual rig: per-frame render time on one core at 640x480 and 1280x1024 (after per-scene "
    "precomputation), and of moving scenes at 640x480"
)

SIZES = ((640, 480), (1280, 1024))
MOVING_SIZE = (640, 480)
LATERAL = {"motion_mm_per_frame": (8.0, 0.0, 0.0), "motion_bounce_frames": 6}
# (scene or None = --render-scene, label, rig options)
MOVING = (
    ("cube", "lateral 8 mm/frame", LATERAL),
    ("turntable", "turntable 2 deg/frame", {"rotation_deg_per_frame": 2.0}),
    (None, "lateral 8 mm/frame", LATERAL),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--render-scene", default="face", metavar="NAME", help="scene for --render (default face)")
    parser.add_argument(
        "--render-frames", type=positive_int, default=60, metavar="N", help="frames timed per row (default 60)"
    )


def _time_rig(rig: object, n: int) -> tuple[list[float], list[float]]:
    from core.patterns import two_shot_patterns

    patterns = two_shot_patterns(rig.projector_size)
    prepared = [rig.prepare(img) for img in patterns.images]
    for i in range(3):  # warm-up
        rig.render(prepared[i % 2])
    times = []
    for i in range(n):
        t = time.perf_counter()
        rig.render(prepared[i % 2])
        times.append(time.perf_counter() - t)
    raw = []
    for i in range(max(5, n // 4)):
        t = time.perf_counter()
        rig.render(patterns.images[i % 2])  # unprepared: gamma + defocus of the pattern every call
        raw.append(time.perf_counter() - t)
    return times, raw


def _row(scene: str, size: tuple[int, int], motion: str, precompute_s: float, times: list, raw: list) -> dict:
    med = float(np.median(times)) * 1e3
    return {
        "scene": scene,
        "resolution": f"{size[0]}x{size[1]}",
        "motion": motion,
        "precompute_s": round(precompute_s, 2),
        "median_ms": round(med, 2),
        "p95_ms": round(float(np.percentile(times, 95)) * 1e3, 2),
        "unprepared_median_ms": round(float(np.median(raw)) * 1e3, 2),
        "frames_per_s": round(1e3 / med, 1),
    }


def run(args: argparse.Namespace) -> list[dict]:
    from drivers.sim.rig import VirtualRig

    scene = getattr(args, "render_scene", "face")
    n = max(5, int(getattr(args, "render_frames", 60)))
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # one core, as the target says
    rows = []
    try:
        for size in SIZES:
            t0 = time.perf_counter()
            rig = VirtualRig.from_preset(scene, camera_size=size)
            precompute_s = time.perf_counter() - t0
            rows.append(_row(scene, size, "still", precompute_s, *_time_rig(rig, n)))
        for name, label, options in MOVING:
            name = name or scene
            t0 = time.perf_counter()
            rig = VirtualRig.from_preset(name, camera_size=MOVING_SIZE, **options)
            precompute_s = time.perf_counter() - t0
            label = label if rig.moving else "still (nothing moves)"
            rows.append(_row(name, MOVING_SIZE, label, precompute_s, *_time_rig(rig, n)))
    finally:
        cv2.setNumThreads(threads)
    return rows


def format_table(rows: list[dict]) -> str:
    head = (
        f"{'scene':<14}{'resolution':>11}  {'motion':<23}{'precompute s':>13}{'median ms':>11}{'p95 ms':>9}"
        f"{'unprepared ms':>15}{'fps':>8}"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['scene']:<14}{r['resolution']:>11}  {r.get('motion', 'still'):<23}{r['precompute_s']:>13.2f}"
            f"{r['median_ms']:>11.2f}{r['p95_ms']:>9.2f}{r['unprepared_median_ms']:>15.2f}{r['frames_per_s']:>8.1f}"
        )
    lines.append(
        "(one core; 'unprepared' = render(ndarray), converting the pattern each call; moving rows: every "
        "frame moves the scene, target <= 30 ms)"
    )
    return "\n".join(lines)
