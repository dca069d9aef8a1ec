"""`slscan project`: show a scheme's patterns on a screen, cyclically, and report the flip timing."""

from __future__ import annotations

import argparse

from app.argtypes import non_negative_float, positive_float
from app.schemes import get_scheme, pattern_options
from core.errors import InputError
from core.patterns import SCHEMES, make_patterns, parse_size

HELP = "show a scheme's patterns fullscreen on a screen (the projector) and measure the flip rate"

EPILOG = """\
examples:
  slscan project --scheme two-shot --screen 1 --hz 60              # frame 1, frame 2, frame 1, ...
  slscan project --scheme one-shot --screen HDMI-1 --size 1920x1080 --seconds 10
  slscan project --scheme graycode --screen 1 --hz 2                # slowly, to look at each image

Esc or q in the window, or Ctrl-C, stops; the measured flip interval and jitter are printed at the
end. `slscan devices` lists the screens (index, name, position, size). The window refuses to run
unless its framebuffer is exactly the screen (and --size, when given) on the chosen screen.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "project", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--scheme", required=True, choices=SCHEMES, help="pattern scheme")
    p.add_argument("--screen", default="0", help="screen index or name (default 0; see `slscan devices`)")
    p.add_argument(
        "--hz",
        type=non_negative_float,
        default=60.0,
        help="pattern rate; 0 = every refresh, paced by vsync (default 60)",
    )
    p.add_argument(
        "--size", metavar="WxH", help="projector resolution; the screen must be exactly this (default: its size)"
    )
    p.add_argument(
        "--seconds", type=positive_float, metavar="S", help="stop after S seconds (default: run until stopped)"
    )
    p.add_argument("--display", metavar="NAME", help="X display, e.g. :0 (default $DISPLAY)")
    p.add_argument("--gamma", type=float, default=1.0, help="output gamma applied to the patterns (default 1: exact)")
    p.add_argument("--brightness", type=float, default=1.0, help="output scale 0..1 (default 1: exact)")
    p.add_argument("--k", type=int, default=7, help="window length in stripes (default 7)")
    p.add_argument("--channels", default="GB", help="two-shot pattern channels (default GB)")
    p.add_argument("--colors", default="RGB", help="one-shot colours (default RGB)")
    p.add_argument("--stripe-width", type=int, default=1, metavar="PX", help="stripe width in projector pixels")
    p.set_defaults(func=run)


def _scheme_options(args: argparse.Namespace) -> dict:
    return pattern_options(get_scheme(args.scheme), args)


def run(args: argparse.Namespace) -> int:
    if not 0 <= args.hz <= 1000:
        raise InputError(f"--hz {args.hz:g} is out of range (0 to 1000; 0 = every refresh)")
    if args.seconds is not None and args.seconds <= 0:
        raise InputError(f"--seconds {args.seconds:g} must be positive")
    size = parse_size(args.size) if args.size else None
    if size is not None:  # bad scheme options fail before a window opens
        make_patterns(args.scheme, size, **_scheme_options(args))

    from drivers.projector.timing import flip_stats
    from drivers.projector.window import PygletProjector

    hz = args.hz or None
    times: list[int] = []
    projector = PygletProjector(args.screen, size, gamma=args.gamma, brightness=args.brightness, display=args.display)
    try:
        patterns = make_patterns(args.scheme, projector.size, **_scheme_options(args))
        projector.load(patterns.images)
        w, h = projector.size
        rate = f"{hz:g} Hz" if hz else "every refresh"
        print(
            f"projecting {len(patterns)} {args.scheme} pattern(s) {w}x{h} on screen {projector.screen_index} "
            f"({projector.screen_name}) at {rate}; Esc/q or Ctrl-C stops",
            flush=True,
        )
        try:
            projector.run(
                list(range(len(patterns))), hz, seconds=args.seconds, on_flip=lambda i, index, t: times.append(t)
            )
        except KeyboardInterrupt:
            pass  # Ctrl-C is the normal way to stop: report and close as usual
        projector.present(None)
    finally:
        projector.close()
    print(f"screen {projector.screen_index}: {flip_stats(times, hz).summary()}")
    return 0
