"""`slscan grab`: save N frames from any camera (PNG per frame + frames.yaml with ids and timestamps)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import yaml

from app.argtypes import positive_float, positive_int
from app.config import load_config
from app.fsutil import atomic_directory
from core.errors import InputError
from core.imageio import write_rgb
from drivers.base import CountingCamera
from drivers.camera.errors import EndOfDumpError
from drivers.camera.spec import open_camera

HELP = "save frames from a camera (GenICam, V4L2, a dump replay, the virtual rig) as PNGs + frames.yaml"

EPILOG = """\
camera SPEC = DRIVER[:ITEM,...], ITEM = key=value (the first may be the driver's main argument):
  genicam:index=0                          the first GenICam device of the producers found
  genicam:serial=21234567,pixel_format=BayerRG8,exposure_us=4000
  genicam:cti=/opt/vendor/lib/x.cti,model=acA1300-200uc
  genicam:cti=viky,serial=0                a virtual camera of the genicam wheel's viky.cti
  v4l2:/dev/video0   v4l2:0,fourcc=MJPG,width=1280,height=720,fps=60
  replay:DUMP        replay:DUMP,realtime=true
  sim                the virtual rig's camera
GenICam producers also come from GENICAM_GENTL64_PATH; `slscan devices` lists the cameras with
a ready-made SPEC. Without --camera, the camera of --config (rig.camera) is used.

output (DIR must not exist or be empty; written all-or-nothing):
  DIR/000000.png ...  RGB PNG per frame, 8-bit, or 16-bit for deeper pixel formats
  DIR/frames.yaml     format: slscan-grab, version: 1, camera, device, and
                      frames: [{file, frame_id, timestamp_ns, pattern}], plus the driver's counters

examples:
  slscan grab --camera genicam:cti=viky,serial=1,pixel_format=Mono8 --frames 10 --out shots/
  slscan grab --camera v4l2:0 --frames 1 --out still/
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "grab", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--camera", metavar="SPEC", help="camera to grab from (see below); default: the config's camera")
    p.add_argument("--config", metavar="FILE", help="rig config whose rig.camera is used without --camera")
    p.add_argument("--frames", type=positive_int, default=1, metavar="N", help="number of frames to save (default 1)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (must not exist or be empty)")
    p.add_argument(
        "--timeout", type=positive_float, default=2.0, metavar="S", help="seconds to wait for each frame (default 2)"
    )
    p.add_argument("--force", action="store_true", help="replace a non-empty --out folder")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.frames < 1:
        raise InputError(f"--frames {args.frames} must be at least 1")
    if not args.timeout > 0:
        raise InputError(f"--timeout {args.timeout:g} must be positive")
    if args.camera is not None:
        spec: object = args.camera
        label = args.camera
    else:
        cfg = load_config(args.config)
        spec = cfg.section("rig").get("camera")
        if not isinstance(spec, dict):
            raise InputError(f"{cfg.path}: key 'rig.camera' must be a mapping with a 'driver'")
        label = f"{cfg.path} rig.camera"
    with atomic_directory(args.out, overwrite=args.force) as tmp:
        camera = open_camera(spec)  # type: ignore[arg-type]
        device = str(camera.device)
        entries: list[dict] = []
        t0 = time.monotonic()
        try:
            camera.start()
            for i in range(args.frames):
                try:
                    frame = camera.grab(timeout_s=args.timeout)
                except EndOfDumpError:
                    warn = f"slscan grab: warning: {device}: the dump ended after {i} of {args.frames} frames"
                    print(warn, file=sys.stderr)
                    break
                name = f"{i:06d}.png"
                write_rgb(tmp / name, frame.image)
                entries.append(
                    {
                        "file": name,
                        "frame_id": int(frame.frame_id),
                        "timestamp_ns": int(frame.timestamp_ns),
                        "pattern": None if frame.pattern is None else int(frame.pattern),
                    }
                )
            elapsed = time.monotonic() - t0
        finally:
            camera.close()
        index: dict = {"format": "slscan-grab", "version": 1, "camera": label, "device": device, "frames": entries}
        if isinstance(camera, CountingCamera):
            index["stats"] = {k: int(v) for k, v in dataclasses.asdict(camera.stats).items()}
        (tmp / "frames.yaml").write_text(yaml.safe_dump(index, sort_keys=False))
    if entries:
        ids = f"frame ids {entries[0]['frame_id']}..{entries[-1]['frame_id']}"
        rate = f", {len(entries) / elapsed:.1f} frames/s" if elapsed > 0 and len(entries) > 1 else ""
        print(f"grabbed {len(entries)} frame(s) from {device} ({ids}{rate}) to {args.out}")
    else:
        print(f"grabbed no frame from {device}; {args.out} holds only frames.yaml")
    return 0
