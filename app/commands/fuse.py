"""`slscan fuse DUMP --out model.ply`: register and integrate a dump's scans into one mesh (Open3D, slscan[fusion])."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from app.argtypes import non_negative_int, volume_mm
from core.errors import InputError

HELP = "fuse a dump's scans into one mesh: registration (ICP) and a TSDF volume; PLY + OBJ and the trajectory"

EPILOG = """\
examples:
  slscan sim render --scene turntable --scheme two-shot --set rotation_deg_per_frame=1 --cycles 181 --out tt/
  slscan fuse tt/ --out model.ply                      # model.ply, model.obj, model.trajectory.csv
  slscan fuse rec/ --out m.ply --voxel-mm 1 --volume-mm=-80,80,-90,70,650,850 --save-partial

Each sliding frame set is decoded, registered to the model built so far (point-to-plane ICP, coarse
then fine, from the pose predicted by constant motion) and integrated into a TSDF volume. A scan that fails
the registration test is dropped (not integrated) and counted; more than --max-dropped in a row is
lost tracking: an error, and with --save-partial the model built until then is written first.
The working volume (camera mm) is what is kept of each scan: the dump's working_volume_mm (a
rendered turntable or hand-held scene has one) unless --volume-mm gives another.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fuse", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("dump", metavar="DUMP", help="frame dump folder (format slscan-dump v1)")
    p.add_argument("--out", required=True, metavar="MODEL.ply", help="mesh to write (and MODEL.obj beside it)")
    p.add_argument("--voxel-mm", type=float, default=None, metavar="V", help="TSDF voxel size in mm (default 0.5)")
    p.add_argument("--calibration", metavar="FILE", help="calibration YAML (default: the dump's own)")
    p.add_argument("--volume-mm", metavar="X0,X1,Y0,Y1,Z0,Z1", help="working volume, camera mm (default: the dump's)")
    p.add_argument("--trajectory", metavar="FILE", help="poses CSV (default: MODEL.trajectory.csv)")
    p.add_argument(
        "--max-dropped",
        type=non_negative_int,
        default=10,
        metavar="N",
        help="scans failing in a row before tracking is lost (default 10)",
    )
    p.add_argument(
        "--min-weight", type=float, default=3.0, metavar="W", help="scans a surface needs to be meshed (default 3)"
    )
    p.add_argument("--motion", choices=("auto", "off"), default="auto", help="two-shot motion handling (as decode)")
    p.add_argument("--save-partial", action="store_true", help="on lost tracking, still write the model built so far")
    p.set_defaults(func=run)


def _progress(done: int, total: int) -> None:
    if sys.stderr.isatty():
        width = 30
        fill = int(width * done / total)
        print(f"\r[{'#' * fill}{'.' * (width - fill)}] {done}/{total} scans", end="", file=sys.stderr, flush=True)


def _write(fuser: object, out: str, trajectory: Path) -> tuple[Path, Path, int]:
    from app.fusion.mesh_io import write_mesh
    from core.trajectory import write_trajectory

    mesh = fuser.mesh()
    ply, obj = write_mesh(mesh, out)
    write_trajectory(trajectory, fuser.poses)
    return ply, obj, len(mesh.triangles)


def run(args: argparse.Namespace) -> int:
    from app.fusion.fuser import DEFAULT_VOXEL_MM
    from app.fusion.mesh_io import mesh_paths
    from app.fusion.offline import FuseOptions, TrackingLostError, fuse_dump
    from app.fusion.open3d_import import open3d
    from core.calibration import Calibration
    from core.dump import read_dump

    open3d()  # the missing extra is said before any work
    voxel = DEFAULT_VOXEL_MM if args.voxel_mm is None else args.voxel_mm
    if not voxel > 0:
        raise InputError(f"--voxel-mm {args.voxel_mm:g}: must be > 0")
    dump = read_dump(args.dump)
    cal = Calibration.load(args.calibration) if args.calibration else dump.calibration()
    ply, _ = mesh_paths(args.out)
    trajectory = Path(args.trajectory) if args.trajectory else ply.with_suffix(".trajectory.csv")
    options = FuseOptions(voxel, volume_mm(args.volume_mm), args.min_weight, args.max_dropped, args.motion)
    try:
        fuser = fuse_dump(dump, cal, options, _progress)
    except TrackingLostError as exc:
        if sys.stderr.isatty():
            print(file=sys.stderr)
        if args.save_partial and exc.fuser.stats.integrated > 0:
            ply, obj, n = _write(exc.fuser, args.out, trajectory)
            print(
                f"slscan fuse: partial model ({exc.fuser.stats.integrated} scans, {n} triangles) in {ply}, {obj}",
                file=sys.stderr,
            )
        raise
    if sys.stderr.isatty():
        print(file=sys.stderr)
    ply, obj, n = _write(fuser, args.out, trajectory)
    s = fuser.stats
    print(
        f"fused {s.integrated} of {s.scans} scans ({s.dropped} dropped) into {n} triangles: {ply}, {obj}, {trajectory}"
    )
    return 0
