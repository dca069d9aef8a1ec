"""`slscan live`: the live scanning session (operator view, or --headless).

Also the session builder the `dump`, `replay` and `bench --live` commands share: a config file
-> devices from the driver registries, the pattern set, the calibration and the depth range.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.argtypes import positive_float, positive_int
from app.capture import CaptureLoop, pattern_order
from app.config import Config, load_config
from app.errors import DeviceError, InputError
from app.owner_thread import HandOver
from app.patterns import SCHEMES, PatternSet, make_patterns
from app.pipeline import DECODE_WORKERS, WORKERS_HELP, LivePipeline, Processor, Result, status_line
from app.rig_devices import make_device, rig_driver
from calibration.model import Calibration
from drivers.base import CAMERAS, PROJECTORS, TRIGGERS
from drivers.camera.pixels import camera_frame_dtype

HELP = "run the live scanning session (virtual rig by default; --config for real hardware)"

EPILOG = """\
examples:
  slscan live                                   # the virtual rig (config/sim.yaml), operator window
  slscan live --headless --frames 600           # same loop, no window: prints the figures, saves the last scan
  slscan live --config rig.yaml                 # real camera, projector and trigger box
  slscan live --headless --frames 300 --record rec/   # and record the checked frames as a dump

keys in the window: space = snapshot (depth TIFF, PLY, PNGs), r = start/stop recording,
m = switch scheme, q / Esc = quit.
Without a display, `slscan live` says so and runs headless.
"""

SIM_MODULE = "drivers.sim.devices"


# ------------------------------------------------------------------------------------ session


@dataclass
class Session:
    """Everything a live run needs, built from one config file."""

    config: Config | None  # None: a replayed dump
    scheme: str
    patterns: PatternSet
    calibration: Calibration
    depth_range_mm: tuple[float, float] | None
    rate_hz: float
    make_devices: Callable[[], tuple[Any, Any, Any]]  # (camera, projector, trigger or None), on the calling thread
    scheme_options: dict = field(default_factory=dict)
    sim: Any = None  # the virtual rig, when the session runs on it (ground truth for tests and benches)
    pace: bool = True  # False: the camera paces itself (a replayed dump)
    source: str = ""  # what the session runs on, for messages
    # the camera frames' dtype, which the decoder's kernels are compiled for before the first set (from the config's
    # camera pixel_format; a camera left in a deeper format than its config says compiles them on its first set)
    frame_dtype: Any = np.uint8

    def make_loop(self, wrap_projector: Callable[[Any], Any] | None = None, **kw: Any) -> CaptureLoop:
        """Open the devices on the calling thread (a pyglet window belongs to it) and load the patterns.

        wrap_projector: applied to the projector first (the view hands its window to the main thread).
        """
        camera, projector, trigger = self.make_devices()
        if projector is not None and wrap_projector is not None:
            projector = wrap_projector(projector)
        if projector is not None:
            projector.load(self.patterns.images)
        kw.setdefault("pace", self.pace)
        return CaptureLoop(camera, projector, trigger, self.scheme, len(self.patterns), rate_hz=self.rate_hz, **kw)

    def processor(self) -> Processor:
        """The session's decoder, its kernels compiled or loaded before any frame arrives (Processor.warm_up): a
        first run on a machine says so on stderr while it compiles."""
        seg = None  # two-shot: the config's scheme.segmentation (checked when the session was built)
        if self.config is not None and self.scheme == "two-shot":
            seg = self.config.get("scheme.segmentation", None, types=str)
        proc = Processor(self.patterns, self.calibration, self.depth_range_mm, seg)
        proc.warm_up(self.frame_dtype, announce=self._announce_compile)
        return proc

    def _announce_compile(self) -> None:
        """Processor.warm_up's announcement: what the operator is told while the decoder compiles."""
        msg = f"slscan: compiling the {self.scheme} decoder (a first run, or changed kernels: about a minute)..."
        print(msg, file=sys.stderr, flush=True)

    def with_scheme(self, scheme: str) -> Session:
        """The same rig with another pattern scheme (the view's `m` key)."""
        if self.config is None:
            raise InputError(f"{self.source}: a replayed dump has one scheme ({self.scheme})")
        return build_session(self.config, scheme=scheme)


def _scheme_options(cfg: Config, scheme: str) -> dict:
    sec = cfg.section("scheme", required=False)
    opts: dict = {}
    if scheme in ("one-shot", "two-shot"):
        if "k" in sec:
            opts["k"] = cfg.get("scheme.k", types=int)
        if "stripe_width" in sec:
            opts["stripe_width"] = cfg.get("scheme.stripe_width", types=int)
    if scheme == "two-shot" and "channels" in sec:
        opts["channels"] = cfg.get("scheme.channels", types=str)
    if scheme == "two-shot" and "segmentation" in sec:
        from app.decode.twoshot import SEGMENTATIONS  # lazy: the decoders compile with numba

        seg = cfg.get("scheme.segmentation", types=str)
        if seg not in SEGMENTATIONS:
            raise InputError(f"{cfg.path}: key 'scheme.segmentation': {seg!r} (choose {', '.join(SEGMENTATIONS)})")
    if scheme == "one-shot" and "colors" in sec:
        opts["colors"] = cfg.get("scheme.colors", types=str)
    return opts


def build_session(
    config: Config | str | os.PathLike | None = None,
    *,
    scheme: str | None = None,
    sim_overrides: dict | None = None,
) -> Session:
    """A Session from a config (default config/sim.yaml). Errors name the file and the key."""
    cfg = config if isinstance(config, Config) else load_config(config)
    scheme = scheme or cfg.get("scheme.name", "two-shot", types=str)
    if scheme not in SCHEMES:
        raise InputError(f"{cfg.path}: key 'scheme.name': unknown scheme {scheme!r} (choose {', '.join(SCHEMES)})")
    rate = float(cfg.get("capture.rate_hz", 60, types=(int, float)))  # type: ignore[arg-type]
    if not 1 <= rate <= 250:
        raise InputError(f"{cfg.path}: key 'capture.rate_hz' must be 1..250, found {rate}")
    depth_range = cfg.get("depth_range_mm", None)
    if depth_range is not None and not (
        isinstance(depth_range, list) and len(depth_range) == 2 and 0 < depth_range[0] < depth_range[1]
    ):
        raise InputError(f"{cfg.path}: key 'depth_range_mm' must be [near, far] with 0 < near < far")

    cam_name, cam_opts = rig_driver(cfg, "camera", CAMERAS)
    proj_name, proj_opts = rig_driver(cfg, "projector", PROJECTORS)
    trig_name, trig_opts = rig_driver(cfg, "trigger", TRIGGERS, required=False)
    opts = _scheme_options(cfg, scheme)

    if "sim" in (cam_name, proj_name, trig_name):
        if cam_name != "sim" or trig_name not in ("sim", None):
            raise InputError(
                f"{cfg.path}: key 'rig': the virtual rig's camera and trigger go together "
                "(its projector may be a real window the virtual camera watches)"
            )
        window = None if proj_name == "sim" else (proj_name, proj_opts)
        return _sim_session(cfg, scheme, opts, rate, depth_range, sim_overrides or {}, window)

    # Real hardware: the projector's size fixes the pattern size; the calibration comes from the config.
    cal_path = cfg.get("calibration", types=str)
    cal_file = (cfg.path.parent / str(cal_path)).resolve()
    if not cal_file.is_file():
        raise InputError(f"{cfg.path}: key 'calibration': file {cal_file} not found (run `slscan calibrate`)")
    calibration = Calibration.load(cal_file)
    patterns = make_patterns(scheme, calibration.projector_size, **opts)
    if trig_name and "cycle" not in trig_opts and "cycle" in inspect.signature(TRIGGERS[trig_name]).parameters:
        trig_opts["cycle"] = len(pattern_order(scheme, len(patterns)))  # the box marks each pattern cycle

    def make_devices() -> tuple[Any, Any, Any]:
        cam = make_device(cfg, "camera", CAMERAS, cam_name, cam_opts)  # type: ignore[arg-type]
        try:
            proj = make_device(cfg, "projector", PROJECTORS, proj_name, proj_opts)  # type: ignore[arg-type]
            if tuple(proj.size) != tuple(calibration.projector_size):
                raise DeviceError(
                    f"projector {proj.name} is {proj.size[0]}x{proj.size[1]} but the calibration "
                    f"{cal_file} says {calibration.projector_size[0]}x{calibration.projector_size[1]}"
                )
            trig = make_device(cfg, "trigger", TRIGGERS, trig_name, trig_opts) if trig_name else None
        except BaseException:
            cam.close()
            raise
        return cam, proj, trig

    rng = tuple(depth_range) if depth_range else None
    session = Session(cfg, scheme, patterns, calibration, rng, rate, make_devices, opts)  # type: ignore[arg-type]
    session.frame_dtype = camera_frame_dtype(cam_opts.get("pixel_format"))
    return session


class WatchedWindow:
    """A real projector window (e.g. pyglet) that the virtual rig's camera watches.

    Every call goes to both: the window shows the pattern on a real screen, the virtual projector
    lights the simulated scene with it. The window's flip time is the one reported.
    """

    def __init__(self, window: Any, sim_projector: Any) -> None:
        self.window, self.sim = window, sim_projector
        self.name, self.size = f"{window.name}+sim", tuple(window.size)

    def load(self, images: Any) -> None:
        self.sim.load(images)
        self.window.load(images)

    def show(self, index: int | None) -> Any:
        self.sim.show(index)  # applies from the next tick, as the window's flip does
        return self.window.show(index)

    def close(self) -> None:
        try:
            self.window.close()
        finally:
            self.sim.close()

    def __getattr__(self, name: str) -> Any:  # request_stop, stop_requested, poll, flips, ...
        return getattr(self.window, name)


def _sim_session(
    cfg: Config,
    scheme: str,
    opts: dict,
    rate: float,
    depth_range: list | None,
    overrides: dict,
    window: tuple[str, dict] | None = None,
) -> Session:
    """The virtual rig (drivers/sim): its true calibration goes with every result and dump.

    window: (driver, options) of a real projector window shown along with the virtual projector.
    """
    try:
        sim_devices = importlib.import_module(SIM_MODULE)
    except ImportError as exc:
        raise DeviceError(f"the virtual rig is not available ({exc})") from None
    if overrides:  # tests and benches: the same config with some `sim:` keys replaced
        cfg = Config(cfg.path, {**cfg.data, "sim": {**cfg.section("sim"), **overrides}})
    devices = sim_devices.make_sim_rig(cfg)
    rig = devices.rig
    calibration = rig.calibration
    patterns = make_patterns(scheme, tuple(devices.projector.size), **opts)
    rng = tuple(depth_range) if depth_range else tuple(rig.depth_range_mm)
    used = {"done": False}

    def make_devices() -> tuple[Any, Any, Any]:
        if used["done"]:  # a second loop (scheme switch) gets a fresh virtual rig
            devs = sim_devices.make_sim_rig(cfg)
        else:
            used["done"] = True
            devs = devices
        if window is None:
            return devs.camera, devs.projector, devs.trigger
        shown = make_device(cfg, "projector", PROJECTORS, window[0], window[1])
        if tuple(shown.size) != tuple(devs.projector.size):
            shown.close()
            raise DeviceError(
                f"projector {shown.name} is {shown.size[0]}x{shown.size[1]} but {cfg.path} key 'sim.projector_size' "
                f"says {devs.projector.size[0]}x{devs.projector.size[1]}"
            )
        return devs.camera, WatchedWindow(shown, devs.projector), devs.trigger

    session = Session(cfg, scheme, patterns, calibration, rng, rate, make_devices, opts, sim=devices)  # type: ignore[arg-type]
    session.frame_dtype = np.uint16 if rig.options.bit_depth == 16 else np.uint8
    return session


# ------------------------------------------------------------------------------------ command


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--config", metavar="FILE", help="rig configuration (default: config/sim.yaml, the virtual rig)")
    p.add_argument("--scheme", choices=SCHEMES, help="pattern scheme (default: the config's scheme.name)")
    p.add_argument("--headless", action="store_true", help="no window: run the loop, print figures, save the last scan")
    p.add_argument("--frames", type=positive_int, metavar="N", help="stop after N camera frames (headless default 300)")
    p.add_argument("--out", metavar="DIR", help="headless: folder for the last scan (default live-YYYYmmdd-HHMMSS)")
    p.add_argument("--record", metavar="DIR", help="record the checked frames as a dump in DIR (must not exist)")
    p.add_argument("--png-level", type=int, default=0, metavar="L", help="PNG level for recordings (0 fastest; 1..9)")
    p.add_argument("--workers", type=positive_int, default=DECODE_WORKERS, help=WORKERS_HELP)
    p.add_argument(
        "--timeout", type=positive_float, default=2.0, metavar="S", help="camera timeout in seconds (default 2)"
    )
    p.set_defaults(func=run)


def open_recorder(session: Session, folder: str | os.PathLike, png_level: int = 0):
    from app.dump import DumpWriter
    from app.recorder import Recorder

    writer = DumpWriter(
        folder,
        session.patterns,
        session.calibration,
        depth_range_mm=session.depth_range_mm,
        extra={"rig": str(session.config.path)},
        png_level=png_level,
    )
    return Recorder(writer)


def run(args: argparse.Namespace) -> int:
    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames {args.frames}: must be at least 1")
    if not args.headless and not os.environ.get("DISPLAY"):
        # The session itself needs no screen: run it headless rather than refuse (say so on stderr).
        print(
            "slscan live: no display for the operator window (DISPLAY is not set): running --headless", file=sys.stderr
        )
        args.headless = True
    if not args.headless:
        from app.view import run_view

        session = build_session(args.config, scheme=args.scheme)
        return run_view(session, args)
    session = build_session(args.config, scheme=args.scheme)
    return run_headless(session, args)


def run_headless(session: Session, args: argparse.Namespace, label: str = "live") -> int:
    frames = args.frames or 300
    out = Path(args.out) if args.out else Path(time.strftime("live-%Y%m%d-%H%M%S"))
    # the decoder first: an error (or Ctrl-C) while it compiles leaves no empty dump behind
    processor = session.processor()
    recorder = open_recorder(session, args.record, args.png_level) if getattr(args, "record", None) else None
    # The devices open on this thread: a projector window (pyglet) stays with it, and this thread
    # serves the window's calls while it waits, so the capture loop's projector thread paces the
    # flips by the trigger, never by the camera's grab (app/owner_thread.py).
    hand_over = HandOver()
    try:
        loop = session.make_loop(wrap_projector=hand_over, timeout_s=args.timeout)
    except BaseException:
        if recorder is not None:
            recorder.close()
        raise
    pipe = LivePipeline(lambda: loop, processor, workers=args.workers, max_frames=frames, recorder=recorder)
    count = "every frame" if frames >= 10**12 else f"{frames} frames"
    print(f"slscan {label}: {session.scheme} on {describe(session)}, {count}", file=sys.stderr)
    interrupted = False
    pipe.start()
    try:
        try:
            last = time.monotonic()
            while pipe.running:
                hand_over.wait(0.1)
                if time.monotonic() - last >= 1.0 and sys.stderr.isatty():
                    last = time.monotonic()
                    print("\r" + status_line(pipe.figures()), end="", file=sys.stderr, flush=True)
        except KeyboardInterrupt:
            interrupted = True
            pipe.stop()
        while pipe.running:  # the loop closes the window through this thread
            hand_over.wait(0.01)
        pipe.join()
    finally:
        hand_over.finish()
        if recorder is not None:
            recorder.close()
    if sys.stderr.isatty():
        print(file=sys.stderr)
    if pipe.error and pipe.capture.frames == 0:  # the devices did not start: the message is all there is
        raise DeviceError(pipe.error)
    fig = pipe.figures()
    print_figures(fig)
    if recorder is not None:
        print(recorder.summary())
        if pipe.capture.tagged > pipe.capture.confirmed:
            print(f"{pipe.capture.tagged - pipe.capture.confirmed} tagged frame(s) next to a break not recorded")
    if pipe.latest is not None:
        save_result(pipe.latest, processor, out)
        print(f"last scan (frames {', '.join(map(str, pipe.latest.frameset.frame_ids))}) written to {out}")
    else:
        print("no depth map was produced: nothing written")
    if pipe.error:
        print(f"slscan {label}: stopped: {pipe.error}", file=sys.stderr)
        return 2 if pipe.latest is None else 1
    if pipe.stop_reason:
        print(f"slscan {label}: stopped cleanly: {pipe.stop_reason}", file=sys.stderr)
    if interrupted:
        print(f"slscan {label}: interrupted; stopped cleanly", file=sys.stderr)
        return 130
    return 0


def describe(session: Session) -> str:
    if session.source:
        return session.source
    return "the virtual rig" if session.sim is not None else str(session.config.path if session.config else "?")


def print_figures(fig: dict) -> None:
    cap = fig["capture"]
    print(
        f"frames in: {fig['frames']} ({fig['frames_per_s']:.1f}/s)  depth maps out: {fig['depth_maps']} "
        f"({fig['depth_per_s']:.1f}/s)  latency p50 {fig['latency_ms_p50']:.1f} ms, p95 {fig['latency_ms_p95']:.1f} ms"
    )
    print(
        f"per stage (median): grab+check {fig['grab_ms_p50']:.1f} ms, decode {fig['decode_ms_p50']:.1f} ms, "
        f"triangulate {fig['triangulate_ms_p50']:.1f} ms"
        + (" (in the decode pass)" if fig.get("triangulated_in_decode") else "")
    )
    print(
        f"dropped {cap['dropped']}  mispaired (refused) {cap['refused']}: duplicates {cap['duplicates']}, "
        f"out of order {cap['out_of_order']}, mistagged {cap['mistagged']}, untracked {cap['untracked']}; "
        f"resyncs {cap['resyncs']}; stale sets {fig['stale_sets']}, stale results {fig['stale_results']}"
    )


def save_result(result: Result, processor: Processor, out: str | os.PathLike) -> Path:
    """Depth TIFF, PLY, stripe pseudo-colour, depth preview and camera PNGs of one result (all or nothing)."""
    from app.fsutil import atomic_directory

    out = Path(out)
    with atomic_directory(out) as tmp:
        write_result_files(result, processor, tmp)
    return out


def write_result_files(result: Result, processor: Processor, folder: Path, stem: str = "") -> None:
    from app import export
    from app.imageio import write_rgb
    from app.view import colourise_depth, stripe_colours

    export.write_depth_tiff(folder / f"{stem}depth.tiff", result.depth)
    write_rgb(folder / f"{stem}stripes.png", stripe_colours(result.stripes))
    write_rgb(folder / f"{stem}depth_preview.png", colourise_depth(result.depth, processor.triangulator.depth_range_mm))
    for p, f in enumerate(result.frameset.frames):
        write_rgb(folder / f"{stem}camera_p{p}.png", f.image)
    export.write_ply(folder / f"{stem}cloud.ply", processor.triangulator.points(result.depth, result.image))
