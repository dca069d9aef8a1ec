"""`slscan replay DUMP`: play a recorded dump through the live pipeline (window, or --headless)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from app.argtypes import positive_float, positive_int
from app.commands.live import add_fusion_arguments, run_headless
from app.live_pipeline import DECODE_WORKERS, WORKERS_HELP
from app.publisher import add_publish_arguments, open_publisher
from core.errors import InputError

HELP = "play a frame dump through the live pipeline and view (or --headless)"

EPILOG = """\
examples:
  slscan replay rec/                         # in the operator window, at the recorded pace
  slscan replay rec/ --headless --out last/  # as fast as it decodes; prints the figures, saves the last scan
  slscan replay rec/ --headless --realtime   # at the recorded pace (as the live session saw it)
  slscan replay rec/ --headless --realtime --publish tcp://127.0.0.1:5556   # and stream its scans
  slscan replay tt/ --headless --realtime --fuse   # live fusion at the recorded pace: model.ply in --out
  slscan replay tt/ --headless --realtime --preload --fuse   # the same, frames from memory (no PNG decoding)

The dump's own tags, calibration and depth range are used (--calibration overrides the calibration).
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("dump", metavar="DUMP", help="a frame dump folder (slscan dump, r in the live view)")
    p.add_argument("--headless", action="store_true", help="no window: print the figures, save the last scan")
    p.add_argument("--realtime", action="store_true", help="headless: play at the recorded pace (window: always)")
    p.add_argument("--calibration", metavar="FILE", help="use this calibration instead of the dump's")
    p.add_argument(
        "--preload",
        action="store_true",
        help="read every frame into memory first: grabs then cost ~0 CPU, as a real camera's (default: read each "
        "frame from its PNG as it is played)",
    )
    p.add_argument("--frames", type=positive_int, metavar="N", help="stop after N frames (default: the whole dump)")
    p.add_argument("--out", metavar="DIR", help="headless: folder for the last scan (default live-YYYYmmdd-HHMMSS)")
    p.add_argument("--workers", type=positive_int, default=DECODE_WORKERS, help=WORKERS_HELP)
    p.add_argument(
        "--timeout", type=positive_float, default=2.0, metavar="S", help="camera timeout in seconds (default 2)"
    )
    add_publish_arguments(p)
    add_fusion_arguments(p)
    p.set_defaults(func=run, record=None, png_level=0)


def replay_session(dump_path: str, calibration: str | None = None, realtime: bool = False, preload: bool = False):
    """A Session whose camera is the replay camera over `dump_path` (no projector, no trigger); preload: the
    camera holds every frame in memory, read before the session starts."""
    from app.session import Session
    from core.calibration import Calibration
    from core.dump import read_dump
    from drivers.camera.replay import ReplayCamera, preload_frames

    dump = read_dump(dump_path)
    cal = Calibration.load(calibration) if calibration else dump.calibration()
    if cal is None:
        raise InputError(f"{dump_path}: the dump carries no calibration; give one with --calibration FILE")
    patterns = dump.patterns()
    n = len(patterns)
    texture = n if dump.texture_indices() else None  # (checks the dump's texture tag: frames tagged n are texture)
    bad = [i for i, f in enumerate(dump.frames) if f.pattern >= n and f.pattern != texture]
    if bad:
        raise InputError(f"{dump_path}/dump.yaml: frames[{bad[0]}].pattern is outside 0..{n - 1}")

    frames = preload_frames(dump) if preload else None

    def make_devices():
        return ReplayCamera(dump, realtime=realtime, frames=frames), None, None

    rate = 60.0
    session = Session(
        None, dump.scheme, patterns, cal, dump.depth_range_mm(), rate, make_devices, pace=False, source=str(dump_path)
    )
    if dump.frames:
        try:  # the decoder is compiled for the frames' dtype before the replay starts (Session.processor)
            dtype = dump.load_frame(0).dtype
        except InputError:
            dtype = None  # an unreadable first frame: the replay camera reports it in its turn
        if dtype in (np.uint8, np.uint16):  # (other frames fail set by set, each with its file named)
            session.frame_dtype = dtype
    session.mosaic = dump.mosaic
    session.working_volume_mm = dump.working_volume_mm()
    session.calibration_source = str(
        Path(calibration).resolve() if calibration else dump.folder / dump.meta["calibration"]
    )
    return session


def run(args: argparse.Namespace) -> int:
    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames {args.frames}: must be at least 1")
    publisher = open_publisher(args)  # bound before the session starts: a bad address is said first
    try:
        return _run(args)
    finally:
        if publisher is not None:
            publisher.close()


def _run(args: argparse.Namespace) -> int:
    if args.headless:
        session = replay_session(args.dump, args.calibration, realtime=args.realtime, preload=args.preload)
        if args.frames is None:
            args.frames = 10**12  # the whole dump: the replay camera ends the run
        return run_headless(session, args, label="replay")
    import os

    from core.errors import DeviceError

    if not os.environ.get("DISPLAY"):
        raise DeviceError("no display for the view (DISPLAY is not set): run `slscan replay DUMP --headless` instead")
    from app.view import run_view

    return run_view(replay_session(args.dump, args.calibration, realtime=True, preload=args.preload), args)
