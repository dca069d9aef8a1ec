"""`slscan bench --speed`: decode + triangulate time per frame set on one core, compiled for two targets.

Frames come from the virtual rig (face scene) at each resolution. The per-frame path is timed
(median of repeats) after the per-calibration precomputation and the numba compile; the ratio is
to one plain numpy pass over the same frames (frame2 - frame1 as int16), the floor of any decoder.
Times are the thread's CPU time (`time.thread_time`), so other work on a shared machine does not
inflate them; the decode runs on one thread (numba threads set to 1).

Every x86-64 host measures twice in one run: the decoder compiled for this CPU ("native") and, in a
subprocess, compiled for an AVX2-only target ("avx2": numba's CPU set to Haswell and its features, no
AVX-512), the instruction set of most laptops and desktops. Each row says whether it is within the
decoder's targets (TARGETS_MS, and at most MAX_RATIO x the numpy pass where that pass is not cached).

Cameras: `3ccd` (one colour per pixel) and `rggb-raw` (the same exposure through an RGGB mosaic, decoded from
the raw frames: a single-chip camera). A raw row times a lone pair, both frames reconstructed in the call (the
decoder's reconstruction cache never holds them), and is judged by its time over the 3-CCD row's of the same
size and target (at most MAX_RAW_FACTOR).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import time

import numpy as np

from app.argtypes import positive_int
from app.errors import InputError

FLAG = "--speed"
KEY = "speed"
HELP = "decode + triangulate time per frame set (one core) at 640x480, 1280x1024, 1920x1080, native and AVX2"

RESOLUTIONS = ((640, 480), (1280, 1024), (1920, 1080))
TARGETS_MS = {"640x480": 3.0, "1280x1024": 10.0}  # two-shot decode + triangulate per pair, one core
MAX_RATIO = 10.0  # x the numpy pass, at the sizes whose frames do not fit in cache
RATIO_SIZES = ("1280x1024", "1920x1080")
TARGETS = ("native", "avx2")
CAMERAS = ("3ccd", "rggb-raw")
MAX_RAW_FACTOR = 1.2  # a raw RGGB pair's time over the 3-CCD pair's
DEFAULT_SIZES = ",".join(f"{w}x{h}" for w, h in RESOLUTIONS)

# LLVM's Haswell features: AVX2, FMA, BMI2 and no AVX-512 (the CPU name alone would keep the host's features)
AVX2_FEATURES = (
    "+avx,+avx2,+bmi,+bmi2,+cmov,+cx16,+f16c,+fma,+fsgsbase,+lzcnt,+movbe,+pclmul,+popcnt,"
    "+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3,+xsave,+xsaveopt"
)
AVX2_ENV = {"NUMBA_CPU_NAME": "haswell", "NUMBA_CPU_FEATURES": AVX2_FEATURES}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--speed-repeats", type=positive_int, default=30, metavar="N", help="timed repeats per case (speed)"
    )
    parser.add_argument(
        "--speed-schemes", default="two-shot", metavar="LIST", help="schemes to time, comma-separated (speed)"
    )
    parser.add_argument(
        "--speed-sizes",
        default=DEFAULT_SIZES,
        metavar="LIST",
        help="camera sizes WxH to time, comma-separated (speed)",
    )
    parser.add_argument(
        "--speed-cameras",
        default=",".join(CAMERAS),
        metavar="LIST",
        help="cameras to time (two-shot): 3ccd, rggb-raw (a raw single-chip mosaic), comma-separated (speed)",
    )
    parser.add_argument(
        "--speed-targets",
        default=",".join(TARGETS),
        metavar="LIST",
        help="compile targets to time: native (this CPU), avx2 (an AVX2-only x86-64), comma-separated (speed)",
    )


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.thread_time()
        fn()
        times.append(time.thread_time() - t0)
    return 1000.0 * float(np.median(times))


def within_target(row: dict) -> bool:
    """Whether a row meets the decoder's speed targets (two-shot only; other schemes have none). A raw
    mosaic's row is judged by its factor over the 3-CCD time (x_3ccd), not by the absolute targets."""
    if row["scheme"] != "two-shot":
        return True
    if row.get("camera", "3ccd") != "3ccd":
        return row["x_3ccd"] <= MAX_RAW_FACTOR
    res = row["resolution"]
    ok = row["median_ms"] <= TARGETS_MS.get(res, float("inf"))
    return ok and (res not in RATIO_SIZES or row["ratio"] <= MAX_RATIO)


def parse_sizes(text: str) -> list[tuple[int, int]]:
    from app.patterns import parse_size

    sizes = [parse_size(s.strip()) for s in text.split(",") if s.strip()]
    if not sizes:
        raise InputError("--speed-sizes: no size given (e.g. 640x480,1280x1024)")
    return sizes


def parse_cameras(text: str) -> list[str]:
    cameras = [c.strip() for c in text.split(",") if c.strip()]
    for c in cameras:
        if c not in CAMERAS:
            raise InputError(f"--speed-cameras: unknown camera {c!r} (choose {', '.join(CAMERAS)})")
    if "3ccd" not in cameras and cameras:
        cameras.insert(0, "3ccd")  # the raw rows are judged against it
    return cameras


def _raw_row(dec_args: tuple, frames: list, repeats: int, ccd_row: dict) -> dict:
    """A raw RGGB pair's row: a pool of copies one longer than the decoder's reconstruction cache, so every
    call reconstructs both frames, as a lone pair does."""
    from app.decode.pipeline import RGB_CACHE_FRAMES, FrameSetDecoder
    from core.mosaic import sample_mosaic

    dec = FrameSetDecoder(*dec_args, mosaic="RGGB")
    raw = [sample_mosaic(f, "RGGB") for f in frames]
    pool = [[f.copy() for f in raw] for _ in range(RGB_CACHE_FRAMES + 1)]
    dec.decode(raw)  # compile / warm caches
    pairs = itertools.cycle(pool)
    row = _timed_row(lambda: dec.stripes_and_depth(next(pairs))[1], raw, repeats, {**ccd_row, "camera": "rggb-raw"})
    row["x_3ccd"] = round(row["median_ms"] / ccd_row["median_ms"], 2)
    row["within_target"] = within_target(row)
    return row


def _timed_row(decode_only, frames: list, repeats: int, row: dict) -> dict:
    """row with the decode's median, the numpy pass over the same frames and their ratio."""
    med = _median_ms(decode_only, repeats)
    a, b = frames[0], frames[-1]
    base = _median_ms(lambda: b.astype(np.int16) - a.astype(np.int16), repeats)
    return {**row, "median_ms": round(med, 3), "numpy_pass_ms": round(base, 3), "ratio": round(med / base, 2)}


def measure(
    schemes: list[str], repeats: int, target: str, sizes: list | None = None, cameras: list[str] | None = None
) -> list[dict]:
    """The speed rows of this process's compile target (named `target` in the rows), per camera size (w, h)
    and camera (two-shot: 3ccd and, if asked, rggb-raw; other schemes 3ccd)."""
    import numba

    from app.decode.pipeline import FrameSetDecoder
    from app.patterns import make_patterns
    from drivers.sim.rig import VirtualRig

    cameras = cameras or ["3ccd"]

    numba.set_num_threads(1)
    rows = []
    for w, h in sizes or RESOLUTIONS:
        rig = VirtualRig.from_preset("face", camera_size=(w, h))
        cal = rig.calibration
        for scheme in schemes:
            ps = make_patterns(scheme, cal.projector_size)
            meta = {"scheme": scheme, "size": list(ps.size), "images": ps.names, **ps.params}
            frames = [rig.render(im) for im in ps.images]
            dec = FrameSetDecoder(scheme, meta, cal, rig.depth_range_mm)
            dec.decode(frames)  # compile / warm caches

            base_row = {"scheme": scheme, "resolution": f"{w}x{h}", "target": target, "camera": "3ccd"}
            row = _timed_row(lambda dec=dec, frames=frames: dec.stripes_and_depth(frames)[1], frames, repeats, base_row)
            row["within_target"] = within_target(row)
            rows.append(row)
            if scheme == "two-shot" and "rggb-raw" in cameras:
                rows.append(_raw_row((scheme, meta, cal, rig.depth_range_mm), frames, repeats, row))
    return rows


def _measure_avx2(schemes: list[str], repeats: int, sizes: list, cameras: list[str]) -> list[dict]:
    """measure() in a subprocess whose numba compiles for AVX2_ENV (numba reads its CPU target once)."""
    code = "import json, sys; from app.bench.speed import measure; print(json.dumps(measure(*json.loads(sys.argv[1]))))"
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    run = subprocess.run(
        [sys.executable, "-c", code, json.dumps([schemes, repeats, "avx2", sizes, cameras])],
        env={**env, **AVX2_ENV},
        capture_output=True,
        text=True,
    )
    if run.returncode != 0:
        last = (run.stderr.strip().splitlines() or ["no output"])[-1]
        raise InputError(f"bench --speed: the AVX2 build failed: {last}")
    return json.loads(run.stdout.strip().splitlines()[-1])


def run(args: argparse.Namespace) -> list[dict]:
    repeats = getattr(args, "speed_repeats", 30)
    schemes = [s.strip() for s in getattr(args, "speed_schemes", "two-shot").split(",") if s.strip()]
    targets = [t.strip() for t in getattr(args, "speed_targets", ",".join(TARGETS)).split(",") if t.strip()]
    for t in targets:
        if t not in TARGETS:
            raise InputError(f"--speed-targets: unknown target {t!r} (choose {', '.join(TARGETS)})")
    sizes = parse_sizes(getattr(args, "speed_sizes", DEFAULT_SIZES))
    cameras = parse_cameras(getattr(args, "speed_cameras", ",".join(CAMERAS)))
    rows = measure(schemes, repeats, "native", sizes, cameras) if "native" in targets else []
    if "avx2" in targets:
        from core.jit import host_features

        if "avx2" not in host_features():
            print("bench --speed: this CPU has no AVX2: the avx2 rows are left out", file=sys.stderr)
        else:
            rows += _measure_avx2(schemes, repeats, [list(s) for s in sizes], cameras)
    order = {t: i for i, t in enumerate(TARGETS)}
    res_order = {f"{w}x{h}": i for i, (w, h) in enumerate(sizes)}
    cam_order = {c: i for i, c in enumerate(CAMERAS)}
    return sorted(
        rows, key=lambda r: (r["scheme"], res_order[r["resolution"]], cam_order[r["camera"]], order[r["target"]])
    )


def format_table(rows: list[dict]) -> str:
    head = (
        f"{'scheme':10s} {'resolution':>10s} {'camera':>8s} {'target':>7s} {'median ms':>10s} {'numpy ms':>9s} "
        f"{'ratio':>6s} {'x 3ccd':>6s} {'sets/s':>7s}  within target"
    )
    lines = [head]
    for r in rows:
        factor = f"{r['x_3ccd']:6.2f}" if "x_3ccd" in r else f"{'':6s}"
        lines.append(
            f"{r['scheme']:10s} {r['resolution']:>10s} {r['camera']:>8s} {r['target']:>7s} {r['median_ms']:10.2f} "
            f"{r['numpy_pass_ms']:9.2f} {r['ratio']:6.1f} {factor} {1000.0 / r['median_ms']:7.1f}  "
            f"{'yes' if r['within_target'] else 'NO'}"
        )
    lines.append(
        "(decode + triangulate per frame set, one core, after per-calibration precomputation; native = compiled "
        "for this CPU, avx2 = for an AVX2-only x86-64; two-shot targets: <= 3 ms at 640x480, <= 10 ms at "
        f"1280x1024, <= {MAX_RATIO:g}x the numpy pass at 1280x1024 and 1920x1080; rggb-raw = a lone raw RGGB pair, "
        f"<= {MAX_RAW_FACTOR:g}x the 3ccd time)"
    )
    return "\n".join(lines)
