"""`slscan patterns`: write a scheme's pattern images and patterns.yaml."""

from __future__ import annotations

import argparse

from app.fsutil import atomic_directory
from app.schemes import get_scheme, pattern_options
from core.pattern_export import write_patterns
from core.patterns import SCHEMES, make_patterns, parse_size

HELP = "write the pattern images of a scheme (PNGs + patterns.yaml) for any projector size"

EPILOG = """\
examples:
  slscan patterns --scheme two-shot --size 1024x768 --out pat/      # 2 images, 256 GB stripes x4
  slscan patterns --scheme one-shot --size 1920x1080 --stripe-width 2 --out pat1/
  slscan patterns --scheme graycode --size 1024x768 --out gray/     # white, black, cols, rows

Every window of k consecutive stripes is unique within one period of the sequence
(one-shot: n(N,k) = N(N-1)^(k-1) = 192 for RGB, k=7; two-shot: n2(m,k) = 2^m m^(k-1) = 256 for
GB, k=7); a projector wider than one period shows the cyclic sequence repeated.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "patterns", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--scheme", required=True, choices=SCHEMES, help="pattern scheme")
    p.add_argument("--size", required=True, metavar="WxH", help="projector resolution, e.g. 1024x768")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (must not exist or be empty)")
    p.add_argument("--k", type=int, default=7, help="window length in stripes (default 7)")
    p.add_argument("--channels", default="GB", help="two-shot pattern channels: GB (default), RG, RGB, ...")
    p.add_argument("--colors", default="RGB", help="one-shot colours, letters from RGBCMYWK (default RGB)")
    p.add_argument("--stripe-width", type=int, default=1, metavar="PX", help="stripe width in projector pixels")
    p.add_argument("--force", action="store_true", help="replace a non-empty --out folder")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    size = parse_size(args.size)
    options = pattern_options(get_scheme(args.scheme), args)
    patterns = make_patterns(args.scheme, size, **options)
    with atomic_directory(args.out, overwrite=args.force) as tmp:
        write_patterns(patterns, tmp)
    period = patterns.params.get("period")
    extra = f", sequence period {period} stripes" if period else ""
    print(f"wrote {len(patterns)} {args.scheme} pattern(s) {size[0]}x{size[1]}{extra} to {args.out}")
    return 0
