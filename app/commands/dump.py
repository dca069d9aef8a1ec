"""`slscan dump`: record raw tagged frames from the rig as a frame dump (format v1); `--repair` a killed one."""

from __future__ import annotations

import argparse
import sys
import time

from app.argtypes import positive_float, positive_int
from app.live_pipeline import LivePipeline
from app.owner_thread import HandOver
from app.termination import exit_status, stopped_by
from core.dump import repair_dump
from core.errors import InputError
from core.patterns import SCHEMES

HELP = "record tagged camera frames from the rig as a frame dump (or --repair one whose writer was killed)"

EPILOG = """\
examples:
  slscan dump --frames 600 --out rec/                 # 10 s of two-shot frames from the virtual rig
  slscan dump --config rig.yaml --frames 120 --out rec2/ --png-level 1
  slscan decode rec/ --out depth/                     # the dump carries its calibration and depth range
  slscan dump --repair rec/                           # after a crash: index = the complete frames
  slscan dump --frames 600 --texture-every 60 --out rec3/   # and a white-light texture frame every second

Only frames whose pattern tag is certain are written (the tag comes from the trigger count and the
flip log, then the pixels must alternate as the patterns do): with two-shot every frame from the
third one on, with Gray code from the second pattern cycle on; every refused frame is counted.
The dump is readable up to its last complete frame at any moment, even if slscan is killed.
An existing --out is never overwritten. PNG level 0 (default) keeps up at 60 Hz with the most
disk (~0.9 MB per 640x480 frame); level 1 halves the size for ~11 ms of one core per frame.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "dump", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--config", metavar="FILE", help="rig configuration (default: config/sim.yaml, the virtual rig)")
    p.add_argument("--scheme", choices=SCHEMES, help="pattern scheme (default: the config's scheme.name)")
    p.add_argument(
        "--frames",
        type=positive_int,
        metavar="N",
        help="number of frames to record (confirmed frames: capture goes on past refused ones)",
    )
    p.add_argument("--out", metavar="DIR", help="the new dump folder (must not exist, or be empty)")
    p.add_argument("--png-level", type=int, default=0, metavar="L", help="PNG compression 0..9 (default 0: fastest)")
    p.add_argument(
        "--timeout", type=positive_float, default=2.0, metavar="S", help="camera timeout in seconds (default 2)"
    )
    p.add_argument(
        "--texture-every",
        type=positive_int,
        metavar="N",
        help="record a white-light texture frame every N frames (tagged texture_pattern; default: the config's "
        "capture.texture_every, else none)",
    )
    p.add_argument("--repair", metavar="DUMP", help="repair a dump whose writer was killed, and exit")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.repair:
        report = repair_dump(args.repair)
        print(f"{args.repair}: {report.summary()}")
        return 0
    if args.frames is None or args.out is None:
        raise InputError("--frames N and --out DIR are required (or --repair DUMP)")
    if args.frames < 1:
        raise InputError(f"--frames {args.frames}: must be at least 1")
    from pathlib import Path

    from app.session import build_session, describe, open_recorder

    out = Path(args.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):  # before opening any device
        raise InputError(f"{out}: already exists; a dump is never overwritten (choose another --out)")

    session = build_session(args.config, scheme=args.scheme)
    if args.texture_every is not None:
        if args.texture_every < 2:
            raise InputError(f"--texture-every {args.texture_every}: must be at least 2 frames")
        session.texture_every = args.texture_every
    recorder = open_recorder(session, args.out, args.png_level)
    # Devices open on this thread, which serves a projector window's calls while it waits (as `live`).
    hand_over = HandOver()
    try:
        loop = session.make_loop(wrap_projector=hand_over, timeout_s=args.timeout)
    except BaseException:
        recorder.close()
        raise
    # N frames recorded, not N camera frames: refused frames are never recorded, so capture goes on past them,
    # up to a bound that ends a session whose frames keep being refused
    camera_limit = 2 * args.frames + 120
    pipe = LivePipeline(lambda: loop, None, max_frames=camera_limit, max_recorded=args.frames)
    pipe.set_recorder(recorder)
    print(f"slscan dump: {session.scheme} frames from {describe(session)} -> {args.out}", file=sys.stderr)
    interrupted: KeyboardInterrupt | None = None
    t0 = time.monotonic()
    try:
        pipe.start()
        while pipe.running:
            hand_over.wait(0.2)
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (app/termination.py)
        interrupted = exc
    finally:
        pipe.stop()
        while pipe.running:
            hand_over.wait(0.01)
        pipe.join()
        hand_over.finish()
        stats = recorder.close()
    elapsed = time.monotonic() - t0
    cap = pipe.capture
    print(
        f"{cap.frames} frames in {elapsed:.1f} s ({cap.frames / max(elapsed, 1e-9):.1f}/s); "
        f"dropped {cap.dropped}, refused {cap.refused} (untagged frames are never recorded)"
    )
    if cap.tagged > cap.confirmed:
        print(f"{cap.tagged - cap.confirmed} tagged frame(s) next to a break not recorded: their tag was unconfirmed")
    print(recorder.summary())
    if stats.write_ms:
        w = sorted(stats.write_ms)
        print(f"write time per frame: median {w[len(w) // 2]:.1f} ms, max {w[-1]:.1f} ms")
    if pipe.error:
        print(f"slscan dump: stopped: {pipe.error}; the dump is finalised", file=sys.stderr)
        return 2
    if recorder.message:
        print(f"slscan dump: {recorder.message}", file=sys.stderr)
        return 2
    if interrupted is not None:
        print(f"slscan dump: {stopped_by(interrupted)}; the dump is finalised", file=sys.stderr)
        return exit_status(interrupted)
    if pipe.stats.recorded < args.frames:
        print(
            f"slscan dump: stopped after {cap.frames} camera frames with {pipe.stats.recorded} of {args.frames} "
            f"frames recorded ({cap.refused} refused, {cap.dropped} dropped); the dump is finalised",
            file=sys.stderr,
        )
        return 2
    return 0
