"""The live session: a config file -> devices from the driver registries, the pattern set, the
calibration and the depth range; and what is kept of it (a recorder, a saved result).

`slscan live`, `dump`, `replay`, `bench --live` and the operator view build their sessions here.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.capture import CaptureLoop, pattern_order
from app.chroma import chroma_warning, stripe_width_for
from app.config import Config, load_config
from app.live_pipeline import LiveDecoder, LiveResult
from app.rig_devices import make_device, rig_driver
from app.schemes import get_scheme
from app.texture import with_texture
from core.calibration import Calibration
from core.chroma import chroma_of_fourcc
from core.depth_range_field import depth_range_field
from core.errors import DeviceError, InputError
from core.patterns import SCHEMES, PatternSet, make_patterns
from drivers.base import CAMERAS, PROJECTORS, TRIGGERS
from drivers.camera.pixels import camera_frame_dtype, camera_mosaic

SIM_MODULE = "drivers.sim.devices"


# ------------------------------------------------------------------------------------ session


RECORD_START_S = 3.0  # a recording starts only with room for this many seconds of frames
SCAN_FRAMES = 8  # a saved scan (depth, cloud, PNGs) takes about as much as this many camera frames


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
    mosaic: str | None = None  # a single-chip camera's Bayer mosaic: its frames are raw (H, W) (core/mosaic.py)
    chroma: str | None = None  # colour subsampled across the rows ("4:2:2", "4:2:0"; core/chroma.py), None = full
    notices: list[str] = field(default_factory=list)  # warnings for the operator, printed by the commands
    calibration_source: str | None = None  # the calibration file read (for the scan sidecars), None = the virtual rig's
    texture_every: int | None = None  # a white-light texture frame every N frames (capture.texture_every), None = off
    # what fusion keeps of each scan (camera mm: x0, x1, y0, y1, z0, z1): the virtual rig scene's or a rendered dump's
    # working volume; None = all of it
    working_volume_mm: tuple[float, ...] | None = None

    def make_loop(self, wrap_projector: Callable[[Any], Any] | None = None, **kw: Any) -> CaptureLoop:
        """Open the devices on the calling thread (a pyglet window belongs to it) and load the patterns.

        wrap_projector: applied to the projector first (the view hands its window to the main thread).
        """
        camera, projector, trigger = self.make_devices()
        if projector is not None and wrap_projector is not None:
            projector = wrap_projector(projector)
        if projector is not None:
            projector.load(with_texture(self.patterns))  # (the texture frame, one past the patterns: app/texture.py)
        kw.setdefault("pace", self.pace)
        kw.setdefault("texture_every", self.texture_every if projector is not None else None)
        return CaptureLoop(camera, projector, trigger, self.scheme, len(self.patterns), rate_hz=self.rate_hz, **kw)

    @property
    def motion(self) -> str:
        """Two-shot motion handling from the config's scheme.motion: auto (default; a replayed dump too) or off."""
        return motion_mode(self.config)

    def frame_bytes(self) -> int:
        """The bytes of one camera frame (a raw mosaic has one sample per pixel), as a PNG of level 0 stores it."""
        w, h = self.calibration.camera_size
        return w * h * (1 if self.mosaic else 3) * np.dtype(self.frame_dtype).itemsize

    def check_outputs(self, scan_folder: str | os.PathLike | None, record_folder: str | os.PathLike | None) -> None:
        """Refuse, before the session starts, a scan folder or recording target that could not take its output:
        not a folder (/dev/full), not writable, or a disk without room for a scan, or for RECORD_START_S seconds
        of frames to record (app/fsutil.check_output_folder)."""
        from app.fsutil import check_output_folder

        if scan_folder is not None:
            check_output_folder(scan_folder, SCAN_FRAMES * self.frame_bytes())
        if record_folder is not None:
            if Path(record_folder).exists() or Path(record_folder).is_symlink():
                raise InputError(f"{record_folder}: already exists; a dump is never overwritten (choose another)")
            check_output_folder(record_folder, int(RECORD_START_S * self.rate_hz) * self.frame_bytes())

    def processor(self) -> LiveDecoder:
        """The session's decoder, its kernels compiled or loaded before any frame arrives (LiveDecoder.warm_up): a
        first run on a machine says so on stderr while it compiles."""
        seg = None  # two-shot: the config's scheme.segmentation (checked when the session was built)
        if self.config is not None and get_scheme(self.scheme).segmentation:
            seg = self.config.get("scheme.segmentation", None, types=str)
        proc = LiveDecoder(self.patterns, self.calibration, self.depth_range_mm, seg, self.motion, self.mosaic)
        proc.warm_up(self.frame_dtype, announce=self._announce_compile)
        return proc

    def _announce_compile(self) -> None:
        """LiveDecoder.warm_up's announcement: what the operator is told while the decoder compiles."""
        msg = f"slscan: compiling the {self.scheme} decoder (a first run, or changed kernels: about a minute)..."
        print(msg, file=sys.stderr, flush=True)

    def with_scheme(self, scheme: str) -> Session:
        """The same rig with another pattern scheme (the view's `m` key)."""
        if self.config is None:
            raise InputError(f"{self.source}: a replayed dump has one scheme ({self.scheme})")
        session = build_session(self.config, scheme=scheme)
        session.texture_every = self.texture_every  # (a command-line choice outlives the switch)
        return session


_OPTION_TYPES = {"k": int, "stripe_width": int, "channels": str, "colors": str}


def _scheme_options(cfg: Config, scheme: str) -> dict:
    sec = cfg.section("scheme", required=False)
    kind = get_scheme(scheme)
    opts: dict = {}
    for key in kind.pattern_options:
        if key == "stripe_width" and sec.get(key) == "auto":
            opts[key] = "auto"  # the width the camera's colour carries: resolved once the camera is known
        elif key in sec:
            opts[key] = cfg.get(f"scheme.{key}", types=_OPTION_TYPES[key])
    if kind.segmentation and "segmentation" in sec:
        from app.decode.twoshot import SEGMENTATIONS  # lazy: the decoders compile with numba

        seg = cfg.get("scheme.segmentation", types=str)
        if seg not in SEGMENTATIONS:
            raise InputError(f"{cfg.path}: key 'scheme.segmentation': {seg!r} (choose {', '.join(SEGMENTATIONS)})")
    motion_mode(cfg)  # (checked when the session is built)
    return opts


def _fit_stripes(
    scheme: str, opts: dict, chroma: str | None, calibration: Calibration, camera: str
) -> tuple[dict, list[str]]:
    """(the scheme options with stripe_width "auto" resolved to the width the camera's colour carries, the
    warnings for the operator: a subsampled-colour camera under stripes too narrow for it)."""
    opts = dict(opts)
    if opts.get("stripe_width") == "auto":
        opts["stripe_width"] = stripe_width_for(chroma, calibration)
    if "stripe_width" not in get_scheme(scheme).pattern_options:
        return opts, []
    width = opts.get("stripe_width", 1)
    warning = chroma_warning(chroma, calibration, int(width), camera)
    return opts, [warning] if warning else []


def _tell(notices: list[str]) -> None:
    """The operator's warnings, on stderr as the session is built (every command that opens the rig)."""
    for line in notices:
        print(line, file=sys.stderr, flush=True)


def motion_mode(cfg: Config | None) -> str:
    """The config's scheme.motion: auto (the default) or off; another value is an InputError naming the key."""
    from app.decode.motion import check_motion_mode  # lazy: the decoders compile with numba

    if cfg is None:
        return "auto"
    return check_motion_mode(cfg.get("scheme.motion", "auto"), f"{cfg.path}: key 'scheme.motion'")


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
    texture_every = cfg.get("capture.texture_every", None, types=int)
    if texture_every is not None and texture_every < 2:
        raise InputError(f"{cfg.path}: key 'capture.texture_every' must be at least 2 frames, found {texture_every}")
    depth_range = depth_range_field(cfg.get("depth_range_mm", None), f"{cfg.path}: key 'depth_range_mm'")

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
        session = _sim_session(cfg, scheme, opts, rate, depth_range, sim_overrides or {}, window)
        session.texture_every = texture_every
        return session

    # Real hardware: the projector's size fixes the pattern size; the calibration comes from the config.
    cal_path = cfg.get("calibration", types=str)
    cal_file = (cfg.path.parent / str(cal_path)).resolve()
    if not cal_file.is_file():
        raise InputError(f"{cfg.path}: key 'calibration': file {cal_file} not found (run `slscan calibrate`)")
    calibration = Calibration.load(cal_file)
    chroma = chroma_of_fourcc(cam_opts.get("fourcc")) if cam_name == "v4l2" else None
    opts, notices = _fit_stripes(scheme, opts, chroma, calibration, f"camera {cam_name}")
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
    session.calibration_source = str(Path(cal_file).resolve())
    session.texture_every = texture_every
    session.frame_dtype = camera_frame_dtype(cam_opts.get("pixel_format"))
    session.mosaic = camera_mosaic(cam_opts.get("pixel_format"))
    session.chroma, session.notices = chroma, notices
    _tell(notices)
    return session


class WatchedWindow:
    """A real projector window (e.g. pyglet) that the virtual rig's camera watches.

    Every call goes to both: the window shows the pattern on a real screen, the virtual projector
    lights the simulated scene with it. The window's flip time is the one reported.
    """

    def __init__(self, window: Any, sim_projector: Any) -> None:
        self.window, self.sim = window, sim_projector
        self.name, self.size = f"{window.name}+sim", tuple(window.size)
        self.thread_bound = window.thread_bound

    def load(self, images: Any) -> None:
        self.sim.load(images)
        self.window.load(images)

    def show(self, index: int | None) -> int | None:
        self.sim.show(index)  # applies from the next tick, as the window's flip does
        return self.window.show(index)

    def poll(self) -> bool:
        return self.window.poll()

    def request_stop(self) -> None:
        self.window.request_stop()

    @property
    def stop_requested(self) -> bool:
        return bool(self.window.stop_requested)

    def close(self) -> None:
        try:
            self.window.close()
        finally:
            self.sim.close()


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
    opts, notices = _fit_stripes(scheme, opts, rig.chroma, calibration, "the virtual camera")
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
    session.frame_dtype = np.uint16 if rig.options.bit_depth > 8 else np.uint8
    session.mosaic = rig.mosaic
    session.chroma, session.notices = rig.chroma, notices
    if rig.scene.working_volume_mm is not None:
        session.working_volume_mm = tuple(float(v) for v in rig.scene.working_volume_mm)
    _tell(notices)
    return session


def open_recorder(session: Session, folder: str | os.PathLike, png_level: int = 0):
    from app.recorder import Recorder
    from core.dump import DumpWriter

    session.check_outputs(None, folder)

    writer = DumpWriter(
        folder,
        session.patterns,
        session.calibration,
        depth_range_mm=session.depth_range_mm,
        extra={"rig": str(session.config.path)},
        png_level=png_level,
        mosaic=session.mosaic,
        texture=True,  # (texture frames may come: every N frames, on a snapshot or on demand)
    )
    return Recorder(writer)


def describe(session: Session) -> str:
    if session.source:
        return session.source
    return "the virtual rig" if session.sim is not None else str(session.config.path if session.config else "?")


def save_result(
    result: LiveResult, processor: LiveDecoder, out: str | os.PathLike, calibration_source: str | None = None
) -> Path:
    """Depth TIFF and 16-bit PNG, PLY with normals, stripe pseudo-colour, depth preview, camera PNGs, the calibration
    and the scan.yaml sidecar of one result (all or nothing)."""
    from app.fsutil import atomic_directory

    out = Path(out)
    with atomic_directory(out) as tmp:
        write_result_files(result, processor, tmp, calibration_source=calibration_source)
    return out


def write_result_files(
    result: LiveResult, processor: LiveDecoder, folder: Path, stem: str = "", calibration_source: str | None = None
) -> None:
    from app import export
    from app.decode.mosaic import to_rgb
    from app.normals import point_normals
    from app.scan_info import CALIBRATION_COPY, live_scan_info
    from core.imageio import write_rgb
    from core.scan_sidecar import write_scan_info

    files = {
        "depth": f"{stem}depth.tiff",
        "depth_png": f"{stem}depth.png",
        "cloud": f"{stem}cloud.ply",
        "stripes": f"{stem}stripes.png",
        "preview": f"{stem}depth_preview.png",
    }
    export.write_depth_tiff(folder / files["depth"], result.depth)
    export.write_depth_png16(folder / files["depth_png"], result.depth)
    write_rgb(folder / files["stripes"], export.stripe_colours(result.stripes.stripe, result.stripes.period))
    write_rgb(folder / files["preview"], export.depth_preview(result.depth, processor.triangulator.depth_range_mm))
    for p, f in enumerate(result.frameset.frames):
        write_rgb(folder / f"{stem}camera_p{p}.png", to_rgb(f.image, f.mosaic))
    texture = result.texture
    if texture is not None:
        files["texture"] = f"{stem}texture.png"
        write_rgb(folder / files["texture"], to_rgb(texture.image, texture.mosaic))
    cloud = processor.triangulator.points(result.depth, result.colour_image)
    cloud.normals = point_normals(result.depth, processor.triangulator.ray)
    export.write_ply(folder / files["cloud"], cloud)
    processor.calibration.save(folder / f"{stem}{CALIBRATION_COPY}")
    info = live_scan_info(
        processor.scheme,
        result.frameset.frames,
        result.frameset.arrival_ns,
        files,
        processor.calibration,
        calibration_source,
        export.DEPTH_PNG_SCALE,
        texture,
    )
    if stem:
        info = dataclasses.replace(info, calibration=f"{stem}{CALIBRATION_COPY}")
    write_scan_info(folder / f"{stem}scan.yaml", info)
