"""`slscan sim`: render frame dumps with ground truth on the virtual rig; list its scene presets."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from app.argtypes import non_negative_int, positive_int
from app.schemes import get_scheme, pattern_options
from core.errors import InputError
from core.patterns import SCHEMES, make_patterns
from core.yamlfile import parse_yaml

HELP = "the virtual rig: render a frame dump with ground truth (render), list scene presets (scenes)"

RENDER_EPILOG = """\
examples:
  slscan sim render --scene face --scheme two-shot --out dump_face/
  slscan sim render --scene cube --scheme graycode --ideal --out gray_cube/
  slscan sim render --scene plane --scheme one-shot --set ambient=0.3 --set noise=false --out d/
  slscan sim render --scene turntable --scheme two-shot --set rotation_deg_per_frame=2 --out r/
  slscan sim render --scene cube --scheme two-shot --set "motion_mm_per_frame=[8, 0, 0]" --out m/

Writes a frame dump (format v1, with the rig's true calibration.yaml and depth_range_mm) and
DUMP/ground_truth/: depth.tiff (float32 Z mm, 0 = no surface), column.tiff and row.tiff
(float32 projector coordinates, NaN where not lit), lit.png (255 = visible and lit). On a moving
scene (objects marked `moves`, with motion_mm_per_frame, rotation_deg_per_frame, ...: see
drivers/sim/motion.py) these are the last frame's, DUMP/ground_truth/frames/NNNNNN/ holds each
frame's, and for whole models (`slscan fuse`, docs/formats.md): surface.ply, the moving object's true
surface as a dense point sample in its own frame (the camera's at frame 0), and poses.csv, its true
pose per frame (a trajectory file).
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sim", help=HELP, description=HELP)
    ssub = p.add_subparsers(dest="sim_command", metavar="SUBCOMMAND", parser_class=type(p))
    r = ssub.add_parser(
        "render",
        help="render one pattern cycle of a scheme into a frame dump plus ground truth",
        description="Render the patterns of a scheme on a scene of the virtual rig into a frame dump.",
        epilog=RENDER_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    r.add_argument("--scene", required=True, help="preset name (see `slscan sim scenes`) or a scene .yaml path")
    r.add_argument("--scheme", required=True, choices=SCHEMES, help="pattern scheme")
    r.add_argument("--out", required=True, metavar="DUMP", help="dump folder to create (must not exist or be empty)")
    r.add_argument("--camera-size", metavar="WxH", help="camera resolution (default 640x480)")
    r.add_argument("--cycles", type=positive_int, default=1, help="pattern cycles to render (default 1)")
    r.add_argument(
        "--texture-every",
        type=positive_int,
        metavar="N",
        help="also a white-light texture frame after every N pattern frames (tagged texture_pattern, never paired)",
    )
    r.add_argument("--ideal", action="store_true", help="no noise, blur, crosstalk, ambient, gamma or shading")
    r.add_argument("--seed", type=non_negative_int, help="noise seed (default 0)")
    r.add_argument(
        "--bit-depth", type=int, choices=(8, 12, 16), help="camera output bits (default 8; 12 fills uint16 frames)"
    )
    r.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a rig option, e.g. ambient=0.3, noise=false, crosstalk=0.2 (repeatable)",
    )
    r.add_argument("--k", type=int, default=7, help="window length in stripes (default 7)")
    r.add_argument("--channels", default="GB", help="two-shot pattern channels (default GB)")
    r.add_argument("--colors", default="RGB", help="one-shot colours (default RGB)")
    r.add_argument("--stripe-width", type=int, default=1, metavar="PX", help="stripe width in projector pixels")
    r.set_defaults(func=run_render)
    s = ssub.add_parser("scenes", help="list the scene presets", description="List the virtual rig's scene presets.")
    s.set_defaults(func=run_scenes)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def parse_overrides(items: list[str]) -> dict:
    out: dict = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--set {item!r}: expected KEY=VALUE (e.g. ambient=0.3)")
        try:
            out[key.strip()] = parse_yaml(value)
        except yaml.YAMLError:
            raise InputError(f"--set {item!r}: the value is not a number, true/false or a [list]") from None
    return out


def run_scenes(args: argparse.Namespace) -> int:
    from drivers.sim.scene import SCENES_DIR, list_presets

    presets = list_presets()
    if not presets:
        raise InputError(f"{SCENES_DIR}: no scene presets there (an incomplete installation: reinstall slscan)")
    width = max(len(n) for n, _ in presets)
    for name, desc in presets:
        print(f"{name:<{width}}  {desc}")
    return 0


def write_ground_truth(gt: object, folder: Path) -> None:
    """depth.tiff (Z mm, 0 = none), column.tiff / row.tiff (NaN where not lit), lit.png (255 = lit)."""
    from core.imageio import write_float_tiff, write_rgb

    folder.mkdir(parents=True, exist_ok=True)
    write_float_tiff(folder / "depth.tiff", gt.depth)
    write_float_tiff(folder / "column.tiff", gt.column)
    write_float_tiff(folder / "row.tiff", gt.row)
    write_rgb(folder / "lit.png", np.where(gt.lit, 255, 0).astype(np.uint8))


def run_render(args: argparse.Namespace) -> int:
    from app.texture import texture_image, texture_index
    from core.dump import WORKING_VOLUME_KEY, DumpWriter
    from core.patterns import parse_size
    from core.surface_sample import write_surface_sample
    from core.trajectory import PoseRow, write_trajectory
    from drivers.sim.rig import VirtualRig
    from drivers.sim.truth import can_sample, surface_sample

    if args.cycles < 1:
        raise InputError(f"--cycles {args.cycles}: must be >= 1")
    out = Path(args.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise InputError(f"{out}: already exists; a dump is never overwritten (choose another --out)")
    overrides = parse_overrides(args.set)
    if args.seed is not None:
        overrides["seed"] = args.seed
    if args.bit_depth is not None:
        overrides["bit_depth"] = args.bit_depth
    if args.camera_size:
        overrides["camera_size"] = parse_size(args.camera_size)
    rig = VirtualRig.from_preset(args.scene, ideal=args.ideal, **overrides)
    options = pattern_options(get_scheme(args.scheme), args)
    patterns = make_patterns(args.scheme, rig.projector_size, **options)
    prepared = [rig.prepare(img) for img in patterns.images]
    every = args.texture_every
    white = rig.prepare(texture_image(patterns)) if every else None
    extra: dict = {"source": f"slscan sim render --scene {rig.scene.name}"}
    if rig.scene.working_volume_mm is not None:
        extra[WORKING_VOLUME_KEY] = list(rig.scene.working_volume_mm)
    moving = rig.moving
    true_poses = []
    gt_dir = out / "ground_truth"
    texture = texture_index(patterns)
    writer = DumpWriter(
        out, patterns, rig.calibration, rig.depth_range_mm, extra=extra, mosaic=rig.mosaic, texture=bool(every)
    )
    with writer:
        frame_ns = round(1e9 / 60)
        n = 0
        shown = 0  # pattern frames since the last texture frame
        for _ in range(args.cycles):
            for i, light in enumerate(prepared):
                steps = [(i, light)]
                shown += 1
                if every and shown == every:  # (a texture frame takes a frame of its own: the scene moves on)
                    steps.append((texture, white))
                    shown = 0
                for tag, image in steps:
                    rec = writer.add(rig.render(image), pattern=tag, frame_id=n + 1, timestamp_ns=n * frame_ns)
                    if moving:  # the scene changes every frame: ground truth per frame as well
                        write_ground_truth(rig.ground_truth, gt_dir / "frames" / Path(rec.file).stem)
                        true_poses.append(PoseRow(n, n + 1, "true", np.linalg.inv(rig.object_pose(n))))
                    n += 1
    gt = rig.ground_truth
    write_ground_truth(gt, gt_dir)
    if moving and rig.moving_shapes:
        write_trajectory(gt_dir / "poses.csv", true_poses)
        if can_sample(rig.moving_shapes):  # (a moving relief, e.g. the face preset, has no closed surface)
            write_surface_sample(gt_dir / "surface.ply", surface_sample(rig.moving_shapes))
    lit = float(gt.lit.mean())
    w, h = rig.camera_size
    print(
        f"wrote {n} {args.scheme} frame(s) {w}x{h} of scene {rig.scene.name!r} to {out} "
        f"(lit {100 * lit:.1f} % of pixels, depth range {rig.depth_range_mm[0]:.0f}-{rig.depth_range_mm[1]:.0f} mm)"
    )
    return 0
