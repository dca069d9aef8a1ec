"""`slscan calibrate`: camera–projector calibration (Gray code + local homographies).

slscan calibrate --from DIR --out FILE [--force]      solve a saved capture offline
slscan calibrate --auto --poses N --out FILE          the virtual rig poses its own board
slscan calibrate --out FILE                           the interactive wizard on the virtual rig
slscan calibrate --config RIG --board B --out FILE    the interactive wizard on a rig (real devices)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from app.argtypes import non_negative_int, positive_float, positive_int
from core.errors import InputError

HELP = "calibrate camera and projector with a printed board and Gray code (wizard, --auto, --from)"

EPILOG = """\
examples:
  slscan calibrate --auto --poses 15 --out cal.yaml          # virtual rig, headless; keeps cal.capture/
  slscan calibrate --from cal.capture --out cal2.yaml         # solve a saved capture again
  slscan calibrate --out cal.yaml                             # operator window, virtual rig
  slscan calibrate --config rig.yaml --board board.yaml --out cal.yaml   # operator window, your rig

A capture folder holds board.yaml and one Gray-code frame dump per pose (pose_000/, pose_001/, ...),
plus optional flat colour levels (response/). The calibration file is written only when the solve
passes its checks (enough poses, tilt variety, low reprojection errors); --force writes it anyway,
with a warning.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("--from", dest="from_dir", metavar="DIR", help="solve a saved calibration capture")
    src.add_argument("--auto", action="store_true", help="virtual rig: pose the simulated board automatically")
    p.add_argument("--out", required=True, metavar="FILE", help="calibration YAML to write")
    p.add_argument(
        "--poses", type=positive_int, default=15, metavar="N", help="--auto: number of board poses (default 15)"
    )
    p.add_argument("--scene", default="checkerboard", help="--auto / wizard: board scene (checkerboard, charuco)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="--auto: pose and noise seed")
    p.add_argument(
        "--capture",
        metavar="DIR",
        help="where --auto / the wizard save the capture (default: FILE without .yaml + .capture)",
    )
    p.add_argument(
        "--camera-gamma",
        type=positive_float,
        metavar="G",
        help="camera response exponent (default: as recorded, else 1)",
    )
    p.add_argument("--config", metavar="FILE", help="wizard: rig configuration (default config/sim.yaml)")
    p.add_argument(
        "--board", metavar="FILE", help="wizard on a rig: the printed board's board.yaml (or key 'board' in --config)"
    )
    p.add_argument("--force", action="store_true", help="write the file even if the solve fails its checks")
    p.set_defaults(func=run)


def default_capture_dir(out: Path) -> Path:
    return out.with_name(out.stem + ".capture")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists() and out.is_dir():
        raise InputError(f"{out}: is a folder; --out names the calibration YAML file to write")
    if str(out.parent) and not out.parent.exists():
        raise InputError(f"{out.parent}: folder does not exist (for --out {out})")
    if args.camera_gamma is not None and not args.camera_gamma > 0:
        raise InputError(f"--camera-gamma {args.camera_gamma}: must be > 0")
    if args.from_dir:
        return solve_and_write(Path(args.from_dir), out, args)
    if args.auto:
        from calibration.auto import auto_capture

        if not 1 <= args.poses <= 200:
            raise InputError(f"--poses {args.poses}: choose 1 to 200 (12 to 20 recommended)")
        capture = Path(args.capture) if args.capture else default_capture_dir(out)
        print(f"capturing {args.poses} poses on the virtual rig (scene {args.scene}) into {capture}")
        auto_capture(capture, args.poses, scene=args.scene, seed=args.seed, progress=lambda s: print("  " + s))
        return solve_and_write(capture, out, args)
    from calibration.wizard import run_wizard  # lazy: pyglet opens a window

    return run_wizard(args)


def solve_and_write(folder: Path, out: Path, args: argparse.Namespace) -> int:
    from calibration import report
    from calibration.capture import open_capture
    from calibration.session import solve_capture
    from calibration.validate import compare

    capture = open_capture(folder)
    b = capture.board
    print(f"solving {folder}: {len(capture.poses)} poses, board {b.type} {b.cols}x{b.rows}")
    result = solve_capture(capture, camera_gamma=args.camera_gamma, progress=lambda s: print("  " + s))
    sol = result.solution
    print(report.views_table(sol))
    cal = sol.calibration
    if cal is None:
        raise InputError(f"{folder}: calibration failed: {'; '.join(sol.problems)}; nothing written")
    print(report.figures(cal))
    if result.true_calibration is not None:
        print(report.truth_errors(compare(cal, result.true_calibration)))
    if result.response is not None:
        print(report.response_text(result.response))
    print(report.verdict(sol))
    if not sol.passed and not args.force:
        raise InputError(f"{out}: not written: {'; '.join(sol.problems)} (use --force to write it anyway)")
    cal.save(out)
    if not sol.passed:
        print(f"warning: {out} written with --force although the solve failed its checks", file=sys.stderr)
    print(f"wrote {out}")
    return 0
