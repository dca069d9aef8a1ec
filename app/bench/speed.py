"""`slscan bench --speed`: decode + triangulate time per frame set on one core.

Frames come from the virtual rig (face scene) at each resolution. The per-frame path is timed
(median of repeats) after the per-calibration precomputation and the numba compile; the ratio is
to one plain numpy pass over the same frames (frame2 - frame1 as int16), the floor of any decoder.
Times are the thread's CPU time (`time.thread_time`), so other work on a shared machine does not
inflate them; the decode runs on one thread (numba threads set to 1).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from app.argtypes import positive_int

FLAG = "--speed"
KEY = "speed"
HELP = "decode + triangulate time per frame set (one core) at 640x480, 1280x1024, 1920x1080"

RESOLUTIONS = ((640, 480), (1280, 1024), (1920, 1080))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--speed-repeats", type=positive_int, default=30, metavar="N", help="timed repeats per case (speed)"
    )
    parser.add_argument(
        "--speed-schemes", default="two-shot", metavar="LIST", help="schemes to time, comma-separated (speed)"
    )


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.thread_time()
        fn()
        times.append(time.thread_time() - t0)
    return 1000.0 * float(np.median(times))


def run(args: argparse.Namespace) -> list[dict]:
    import numba

    from app.decode.pipeline import FrameSetDecoder
    from app.patterns import make_patterns
    from drivers.sim.rig import VirtualRig

    numba.set_num_threads(1)
    repeats = getattr(args, "speed_repeats", 30)
    schemes = [s.strip() for s in getattr(args, "speed_schemes", "two-shot").split(",") if s.strip()]
    rows = []
    for w, h in RESOLUTIONS:
        rig = VirtualRig.from_preset("face", camera_size=(w, h))
        cal = rig.calibration
        for scheme in schemes:
            ps = make_patterns(scheme, cal.projector_size)
            meta = {"scheme": scheme, "size": list(ps.size), "images": ps.names, **ps.params}
            frames = [rig.render(im) for im in ps.images]
            dec = FrameSetDecoder(scheme, meta, cal, rig.depth_range_mm)
            dec.decode(frames)  # compile / warm caches

            def decode_only(dec=dec, frames=frames):
                return dec.stripes_and_depth(frames)[1]

            med = _median_ms(decode_only, repeats)
            a, b = frames[0], frames[-1]
            base = _median_ms(lambda a=a, b=b: b.astype(np.int16) - a.astype(np.int16), repeats)
            rows.append(
                {
                    "scheme": scheme,
                    "resolution": f"{w}x{h}",
                    "median_ms": round(med, 3),
                    "numpy_pass_ms": round(base, 3),
                    "ratio": round(med / base, 2),
                }
            )
    return rows


def format_table(rows: list[dict]) -> str:
    head = f"{'scheme':10s} {'resolution':>10s} {'median ms':>10s} {'numpy ms':>9s} {'ratio':>6s} {'sets/s':>7s}"
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['scheme']:10s} {r['resolution']:>10s} {r['median_ms']:10.2f} {r['numpy_pass_ms']:9.2f} "
            f"{r['ratio']:6.1f} {1000.0 / r['median_ms']:7.1f}"
        )
    lines.append("(decode + triangulate per frame set, one core, after per-calibration precomputation)")
    return "\n".join(lines)
