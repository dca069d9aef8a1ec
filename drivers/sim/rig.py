"""The virtual rig: a ray-cast scene seen by a simulated camera under a simulated projector.

Per scene (and per board pose) everything that does not depend on the pattern is
precomputed: camera ray hits, normals, reflectance (supersampled on calibration boards),
projector coordinates, projector shadows, shading and the ambient image. A frame is then three
passes (drivers/sim/kernels.py: nearest-pixel pattern lookup + reflectance + ambient + crosstalk;
OpenCV's PSF blur; noise + clipping + response LUT): ~4 ms at 640x480 on one core, so a live
session on the virtual rig runs at 60 Hz (`slscan bench --render`).

With moving objects (drivers/sim/motion.py) the static shapes' part is precomputed once and each
frame re-casts only the rays that can meet a moving shape (drivers/sim/moving.py); the result is
the full precomputation at that frame's pose (`reference_motion=True` runs that instead, for tests).
With `render_ahead`, the next frame is composed on a background thread as soon as `render` returns
(its geometry does not depend on the pattern), so a caller that waits between frames (a live
session on its trigger) pays only for forming the image (~4 ms) on its own thread.

Image formation, per camera pixel with surface albedo rho (RGB), projector light P (RGB):
    P        = black_level + brightness * (pattern / 255) ** projector_gamma   (defocus-blurred)
    linear   = exposure * (rho * (g * P + ambient * ambient_color) + specular_lobe * P)
    linear  <- crosstalk @ linear, PSF blur, + shot and read noise
    output   = (2**bits - 1) * clip(linear, 0, 1) ** (1 / camera_gamma)
           (12 bits: shifted to fill 16, as a deep GenICam camera's frames; with `bayer`, one channel per site)
g = cos(incidence) * (d_ref / d)^2 where lit (0 in projector shadow or outside its image).
`ideal=True` turns every effect off (g = 1 where lit), so a white plane returns the pattern exactly.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass, field, fields

import cv2
import numpy as np

from core.calibration import Calibration
from core.chroma import chroma_name, subsample_chroma
from core.errors import InputError
from core.mosaic import mosaic_name, sample_mosaic
from drivers.sim.kernels import affine3, light_to_linear, sensor, warm_up
from drivers.sim.motion import MOTION_KEYS, Motion
from drivers.sim.optics import Geometry, camera_rays, project
from drivers.sim.scene import Board, Scene, SceneError, load_scene
from drivers.sim.shapes import Shape

# Camera R, G, B (rows) produced by projector R, G, B (columns): ~10 % leak, a Bayer-like camera.
DEFAULT_CROSSTALK = np.array([[1.00, 0.10, 0.02], [0.08, 1.00, 0.11], [0.02, 0.09, 1.00]])


@dataclass
class RigOptions:
    """The optical and sensor effects (keyword overrides of `VirtualRig.from_preset`)."""

    bit_depth: int = 8  # 8, 12 (uint16 frames, samples shifted to fill 16 bits) or 16
    seed: int = 0
    # projector
    projector_gamma: float = 2.2  # light = (value / 255) ** gamma
    black_level: float = 0.02  # light leak at value 0, fraction of white
    brightness: float = 1.0
    defocus_sigma_px: float = 0.35  # Gaussian defocus, projector pixels (0 = sharp)
    # camera
    exposure: float = 0.75  # linear signal of a white surface facing the projector at d_ref, full white
    camera_gamma: float = 1.8  # output = linear ** (1 / camera_gamma)
    psf_sigma_px: float = 0.6  # lens blur, camera pixels at 640 px width (scaled with the width)
    crosstalk: float | list | bool = 0.10  # largest off-diagonal leak, or a 3x3 matrix, or False
    noise: bool = True
    full_well: float = 6000.0  # electrons at full scale (shot noise)
    read_noise: float = 0.004  # fraction of full scale (~1 DN at 8 bit)
    # scene lighting
    ambient: float = 0.08  # ambient illuminance relative to projector white at d_ref
    ambient_color: tuple[float, float, float] = (1.0, 0.92, 0.78)  # warm room light
    shading: bool = True  # cos(incidence) and 1/d^2 falloff of the projector light
    specular: bool = True
    supersample: int = 4  # per axis, reflectance of anti-aliased (board) surfaces
    # motion of the objects marked `moves` (drivers/sim/motion.py); not effects: `ideal` keeps them
    motion_mm_per_frame: tuple[float, float, float] = (0.0, 0.0, 0.0)  # translation per frame, camera mm
    motion_bounce_frames: int = 0  # > 0: the translation turns back after this many frames, and again
    rotation_deg_per_frame: float = 0.0  # turn per frame about rotation_axis
    rotation_axis: tuple[float, float, float] = (0.0, -1.0, 0.0)  # direction, camera frame (default: up)
    rotation_center_mm: tuple[float, float, float] | None = None  # a point on the axis; None = moving objects' centre
    wander_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)  # hand-held path: translation amplitudes, camera mm
    wander_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # and rotation amplitudes, degrees
    wander_period_frames: float = 240.0  # its typical period
    wander_seed: int = 0  # its phases
    render_ahead: bool = False  # moving scenes: compose the next frame on a background thread (the same images)
    # a single-chip sensor: its mosaic (RGGB, GRBG, GBRG, BGGR; true = RGGB), frames raw (H, W), one channel per
    # site; false = one colour per pixel, as the paper's 3-CCD camera
    bayer: bool | str = False
    # colour subsampled across the rows as a webcam's YUYV (4:2:2) or MJPEG (4:2:0) delivers it (core/chroma.py);
    # None = full colour
    chroma: str | None = None

    def crosstalk_matrix(self) -> np.ndarray:
        c = self.crosstalk
        if c is False or c is None:
            return np.eye(3)
        if c is True:
            return DEFAULT_CROSSTALK.copy()
        if isinstance(c, int | float):
            off = DEFAULT_CROSSTALK - np.eye(3)
            return np.eye(3) + off * (float(c) / off.max())
        return np.asarray(c, np.float64).reshape(3, 3)


IDEAL = {
    "projector_gamma": 1.0,
    "black_level": 0.0,
    "brightness": 1.0,
    "defocus_sigma_px": 0.0,
    "exposure": 1.0,
    "camera_gamma": 1.0,
    "psf_sigma_px": 0.0,
    "crosstalk": False,
    "noise": False,
    "ambient": 0.0,
    "shading": False,
    "specular": False,
}

GEOMETRY_KEYS = {f.name for f in fields(Geometry)}
OPTION_KEYS = {f.name for f in fields(RigOptions)}


@dataclass
class GroundTruth:
    """What the camera sees at each pixel centre, for the last rendered frame."""

    depth: np.ndarray  # (H, W) float32 Z in mm, 0 = no surface
    column: np.ndarray  # (H, W) float32 projector column (pixel centres at integers), NaN where not lit
    row: np.ndarray  # (H, W) float32 projector row, NaN where not lit
    lit: np.ndarray  # (H, W) bool: a surface is visible and the projector lights it
    points: np.ndarray = field(repr=False)  # (H, W, 3) float32 camera-frame points, 0 = none

    @property
    def visible(self) -> np.ndarray:
        return self.depth > 0


@dataclass(frozen=True)
class PreparedPattern:
    """A projector image converted once to linear light (gamma, black level, defocus)."""

    linear: np.ndarray  # (Hp, Wp, 3) float32


class VirtualRig:
    """One scene, one camera, one projector; `render(pattern)` returns the camera image."""

    def __init__(self, scene: Scene, geometry: Geometry, options: RigOptions, reference_motion: bool = False) -> None:
        self.scene = scene
        self.geometry = geometry
        self.options = options
        where = str(scene.path or scene.name)
        geometry.check(where)
        self._check_options(where)
        self._K = geometry.camera_matrix()
        self._dist = np.asarray(geometry.camera_distortion, np.float64)
        self._Kp = geometry.projector_matrix()
        self._distp = np.asarray(geometry.projector_distortion, np.float64)
        self._R, self._T = geometry.extrinsics()
        self._Cp = -self._R.T @ self._T
        self._d_ref = float(np.linalg.norm(np.asarray(geometry.projector_target_mm) - self._Cp))
        self._crosstalk = options.crosstalk_matrix()
        w, h = geometry.camera_size
        self._rays = camera_rays(self._K, self._dist, (w, h)).reshape(-1, 3)
        self._rng = np.random.default_rng(options.seed)
        n = w * h * 3
        self._noise_bank = self._rng.standard_normal(2 * n + 4096, dtype=np.float32) if options.noise else None
        self._lut = self._make_lut()
        warm_up(self._lut.dtype)
        self._base_shapes = list(scene.shapes)
        self._lock = threading.RLock()  # a render never sees half of a re-precomputation
        self.frame_index = 0  # renders so far (drives motion)
        self._motion_step = 0
        self._motion = Motion.from_options(options, self._base_shapes)
        self._moves = self._motion.active and any(s.moves for s in self._base_shapes)
        wp, hp = geometry.projector_size
        # projector-normalised bound beyond which a point cannot be in the projector image
        self._lim = np.abs(np.linalg.solve(self._Kp, [[-0.5, wp - 0.5], [-0.5, hp - 0.5], [1, 1]])[:2]).max() * 1.5
        self._layer = None  # the moving rig's per-frame composition (drivers/sim/moving.py)
        self._gt: GroundTruth | None = None
        self._black: PreparedPattern | None = None
        self._mix32 = np.ascontiguousarray(self._crosstalk, np.float32)
        self._buf: np.ndarray | None = None
        self._buf2: np.ndarray | None = None
        self._prep_lut = (
            options.black_level + options.brightness * (np.arange(256) / 255.0) ** options.projector_gamma
        ).astype(np.float32)
        self._slot = 0  # the moving rig's buffer set holding the frame last rendered
        self._ahead: _Ahead | None = None  # the next frame, being composed on a background thread
        if self._moves and not reference_motion:
            from drivers.sim.moving import MovingLayer

            self._layer = MovingLayer(self, slots=2 if options.render_ahead else 1)
            self._layer.build_static(self._base_shapes)
            self._compose(check=True)
        else:
            self._precompute(self._base_shapes)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_preset(cls, name: str, ideal: bool = False, **overrides: object) -> VirtualRig:
        """A rig over a named preset (config/scenes/NAME.yaml) or a scene file path.

        Overrides are Geometry fields (camera_size, projector_size, ...) or RigOptions fields
        (noise, ambient, seed, bit_depth, ...). With ideal=True every effect is off unless
        overridden, and the scene file's `effects` are ignored.
        """
        scene = load_scene(name)
        return cls.from_scene(scene, ideal=ideal, **overrides)

    @classmethod
    def from_scene(
        cls, scene: Scene, ideal: bool = False, reference_motion: bool = False, **overrides: object
    ) -> VirtualRig:
        """As from_preset. reference_motion=True: moving frames by the full re-precomputation (slow; tests)."""
        where = str(scene.path or scene.name)
        opts: dict = {}
        if ideal:
            opts.update(IDEAL)
        for key, value in scene.effects.items():
            if key not in OPTION_KEYS:
                known = ", ".join(sorted(OPTION_KEYS))
                raise SceneError(f"{where}: field 'effects.{key}' is unknown (known: {known})")
            if not ideal or key in MOTION_KEYS:  # ideal drops the effects, not the scene's motion
                opts[key] = value
        geo: dict = dict(scene.geometry)
        for key, value in overrides.items():
            if key in GEOMETRY_KEYS:
                geo[key] = value
            elif key in OPTION_KEYS:
                opts[key] = value
            else:
                known = ", ".join(sorted(GEOMETRY_KEYS | OPTION_KEYS))
                raise InputError(f"virtual rig: unknown option {key!r} (known: {known})")
        for key in ("camera_size", "projector_size"):
            if key in geo:
                geo[key] = _int_pair(geo[key], key, where)
        for key, value in list(geo.items()):
            if isinstance(value, list):
                geo[key] = tuple(value)
        triples = ("ambient_color", "motion_mm_per_frame", "rotation_axis", "rotation_center_mm")
        triples += ("wander_mm", "wander_deg")
        for key in triples:
            if key in opts and isinstance(opts[key], list):
                opts[key] = tuple(opts[key])
        try:
            geometry = Geometry(**geo)
            options = RigOptions(**opts)
        except TypeError as exc:
            raise InputError(f"{where}: bad rig option ({exc})") from None
        return cls(scene, geometry, options, reference_motion=reference_motion)

    def _check_options(self, where: str) -> None:
        o = self.options

        def bad(key: str, msg: str) -> InputError:
            return InputError(f"{where}: option '{key}' {msg}, found {getattr(o, key)!r}")

        if o.bit_depth not in (8, 12, 16):
            raise bad("bit_depth", "must be 8, 12 or 16")
        mosaic_name(o.bayer, f"{where}: option 'bayer'")
        if chroma_name(o.chroma, f"{where}: option 'chroma'") is not None and o.bayer:
            raise bad("chroma", "does not go with a Bayer sensor (a webcam's colour is subsampled after demosaicing)")
        for key in ("projector_gamma", "camera_gamma", "exposure", "full_well"):
            if not (isinstance(getattr(o, key), int | float) and getattr(o, key) > 0):
                raise bad(key, "must be a number > 0")
        for key in ("black_level", "brightness", "defocus_sigma_px", "psf_sigma_px", "read_noise", "ambient"):
            if not (isinstance(getattr(o, key), int | float) and getattr(o, key) >= 0):
                raise bad(key, "must be a number >= 0")
        if not (isinstance(o.supersample, int) and 1 <= o.supersample <= 16):
            raise bad("supersample", "must be a whole number 1..16")
        if len(o.ambient_color) != 3 or min(o.ambient_color) < 0:
            raise bad("ambient_color", "must be [r, g, b] >= 0")

        def triple(v: object) -> bool:
            return isinstance(v, list | tuple) and len(v) == 3 and all(_finite(x) for x in v)

        if not triple(o.motion_mm_per_frame):
            raise bad("motion_mm_per_frame", "must be [x, y, z] mm")
        if not (isinstance(o.motion_bounce_frames, int) and not isinstance(o.motion_bounce_frames, bool)):
            raise bad("motion_bounce_frames", "must be a whole number of frames >= 0 (0 = never turn back)")
        if o.motion_bounce_frames < 0:
            raise bad("motion_bounce_frames", "must be a whole number of frames >= 0 (0 = never turn back)")
        if not _finite(o.rotation_deg_per_frame):
            raise bad("rotation_deg_per_frame", "must be a number (degrees per frame)")
        if not triple(o.rotation_axis) or not np.any(np.asarray(o.rotation_axis, np.float64)):
            raise bad("rotation_axis", "must be a direction [x, y, z], not all zero")
        if not isinstance(o.render_ahead, bool):
            raise bad("render_ahead", "must be true or false")
        if o.rotation_center_mm is not None and not triple(o.rotation_center_mm):
            raise bad("rotation_center_mm", "must be a point [x, y, z] in mm (or left out: the moving objects' centre)")
        for key in ("wander_mm", "wander_deg"):
            if not triple(getattr(o, key)):
                raise bad(key, "must be [x, y, z] amplitudes")
        if not (_finite(o.wander_period_frames) and o.wander_period_frames > 0):
            raise bad("wander_period_frames", "must be a number of frames > 0")
        if not (isinstance(o.wander_seed, int) and not isinstance(o.wander_seed, bool) and o.wander_seed >= 0):
            raise bad("wander_seed", "must be a whole number >= 0")
        try:
            M = o.crosstalk_matrix()
        except (ValueError, TypeError):
            raise bad("crosstalk", "must be a number, true/false or a 3x3 matrix") from None
        if not np.all(np.isfinite(M)) or np.any(M < 0) or abs(np.linalg.det(M)) < 1e-6:
            raise bad("crosstalk", "must give a non-negative, invertible 3x3 matrix")

    # ------------------------------------------------------------------ public properties
    @property
    def camera_size(self) -> tuple[int, int]:
        return self.geometry.camera_size

    @property
    def projector_size(self) -> tuple[int, int]:
        return self.geometry.projector_size

    @property
    def calibration(self) -> Calibration:
        """The true calibration, with the true colour mixing (columns scaled to a unit diagonal)."""
        M = self._crosstalk / np.diag(self._crosstalk)[None, :]
        cal = self.geometry.calibration(color_mixing=M)
        # The decoders linearise camera values with it before unmixing (a calibration solve measures it).
        cal.extra["camera_gamma"] = float(self.options.camera_gamma)
        return cal

    @property
    def depth_range_mm(self) -> tuple[float, float]:
        return self.scene.depth_range_mm

    @property
    def ground_truth(self) -> GroundTruth:
        """The truth of the frame last rendered (before any render: of frame 0)."""
        with self._lock:
            if self._gt is None:
                self._gt = self._truth(*self._layer.ground_truth(self._slot))
            return self._gt

    @property
    def moving(self) -> bool:
        """Whether frames differ by more than noise: objects marked `moves` and a motion option set."""
        return self._moves

    def object_pose(self, step: int) -> np.ndarray:
        """4x4 map of the moving objects from frame 0 to frame `step` (camera mm): X_step = M X_0. The object's
        frame of drivers/sim/truth.py is the camera frame at frame 0; identity on a still rig."""
        M = np.eye(4)
        if self._moves:
            M[:3, :3], M[:3, 3] = self._motion.pose(step)
        return M

    @property
    def moving_shapes(self) -> list[Shape]:
        """The shapes that move (at frame 0): the object a turntable or a hand turns."""
        return [s for s in self._base_shapes if s.moves]

    @property
    def board(self) -> Board | None:
        return self.scene.board

    @property
    def max_value(self) -> int:
        """The full-scale value of a frame (12 bits: 4095 shifted to fill 16)."""
        bits = self.options.bit_depth
        return ((1 << bits) - 1) << (4 if bits == 12 else 0)

    @property
    def chroma(self) -> str | None:
        """The camera's chroma subsampling ("4:2:2", "4:2:0"; core/chroma.py), None for full colour."""
        return chroma_name(self.options.chroma, "option 'chroma'")

    @property
    def mosaic(self) -> str | None:
        """The sensor's Bayer mosaic (core/mosaic.py), None for one colour per pixel."""
        return mosaic_name(self.options.bayer, "option 'bayer'")

    def projector_light(self, levels: np.ndarray | int) -> np.ndarray:
        """True linear light of projector levels 0..255 (1 = full white): black level, brightness, gamma."""
        o = self.options
        return o.black_level + o.brightness * (np.asarray(levels, np.float64) / 255.0) ** o.projector_gamma

    def camera_response(self, linear: np.ndarray | float) -> np.ndarray:
        """True camera output (before quantisation and noise) of a linear signal (1 = full scale)."""
        x = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
        return self.max_value * x ** (1.0 / self.options.camera_gamma)

    def set_board_pose(self, rvec: np.ndarray, tvec: np.ndarray) -> None:
        """Pose the scene's calibration board (board frame -> camera, OpenCV rvec/tvec, mm)."""
        board = self.scene.board
        if board is None:
            raise InputError(f"scene {self.scene.name!r} has no calibration board (try 'checkerboard' or 'charuco')")
        rvec = np.asarray(rvec, np.float64).reshape(3)
        tvec = np.asarray(tvec, np.float64).reshape(3)
        if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))) or tvec[2] <= 0:
            raise InputError(f"board pose rvec={rvec.tolist()} tvec={tvec.tolist()} is not in front of the camera")
        R, _ = cv2.Rodrigues(rvec)
        i = board.shape_index
        old = (self._base_shapes[i], board.rvec, board.tvec)
        shape = dataclasses.replace(old[0], R=R, c=tvec)
        with self._lock:
            self._base_shapes[i] = self.scene.shapes[i] = shape
            board.rvec, board.tvec = rvec, tvec
            try:
                self._rebuild()
            except InputError:  # e.g. posed out of view: keep the previous pose, say why
                self._base_shapes[i] = self.scene.shapes[i] = old[0]
                board.rvec, board.tvec = old[1], old[2]
                if self._layer is not None:  # the full precomputation raised before changing anything
                    self._rebuild()
                raise

    def board_corners_image(self) -> np.ndarray:
        """True camera pixel coordinates (N, 2) of the board's inner corners at its current pose."""
        board = self.scene.board
        if board is None:
            raise InputError(f"scene {self.scene.name!r} has no calibration board")
        R, _ = cv2.Rodrigues(board.rvec)
        X = board.object_points() @ R.T + board.tvec
        return project(X, self._K, self._dist, np.eye(3), np.zeros(3))

    # ------------------------------------------------------------------ precomputation
    def _current_shapes(self) -> list[Shape]:
        return self._motion.shapes_at(self._base_shapes, self._motion_step)

    def _rebuild(self) -> None:
        """After a static shape changed (a board pose): the whole precomputation again."""
        if self._layer is None:
            self._precompute(self._current_shapes())
            return
        self._drop_ahead()
        self._layer.build_static(self._current_shapes())
        self._compose(check=True)

    def _compose(self, check: bool = False) -> None:
        """The moving rig: the buffers of the current motion step (composed ahead if they were);
        `check`: refuse an impossible set-up as a still scene does (a later frame with nothing in
        view just shows nothing)."""
        ahead, self._ahead = self._ahead, None
        if ahead is not None and ahead.step == self._motion_step and not check:
            ahead.join()
            self._slot = ahead.slot
        else:
            if ahead is not None:
                ahead.join(raise_error=False)
            self._slot = (self._slot + 1) % len(self._layer.sets) if not check else self._slot
            self._layer.compose(self._current_shapes(), self._slot)
        buf = self._layer.sets[self._slot]
        w, h = self.geometry.camera_size
        self._coef = buf.coef.reshape(h, w, 3)
        self._ambient = buf.amb.reshape(h, w, 3)
        self._map = buf.map.reshape(h, w, 2)
        self._gt = None
        if check:
            visible, lit = self._layer.visible_and_lit(self._slot)
            where = str(self.scene.path or self.scene.name)
            if not visible:
                raise InputError(f"{where}: impossible set-up: the camera sees no surface of the scene")
            if not lit:
                raise InputError(f"{where}: impossible set-up: the projector lights nothing the camera sees")

    def _cast(self, shapes: list[Shape], o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t_best = np.full(len(d), np.inf)
        sid = np.full(len(d), -1, np.int32)
        face = np.zeros(len(d), np.int8)
        for i, s in enumerate(shapes):
            t, f = s.intersect(o, d)
            closer = t < t_best
            t_best = np.where(closer, t, t_best)
            sid = np.where(closer, i, sid)
            face = np.where(closer, f, face)
        return t_best, sid, face

    def _precompute(self, shapes: list[Shape]) -> None:
        """Everything that does not depend on the pattern, for these shapes (the full computation)."""
        w, h = self.geometry.camera_size
        where = str(self.scene.path or self.scene.name)
        surf = self._surface(shapes)
        if surf is None:
            raise InputError(f"{where}: impossible set-up: the camera sees no surface of the scene")
        if not surf["lit_idx"].size:
            raise InputError(f"{where}: impossible set-up: the projector lights nothing the camera sees")
        self._coef = surf["coef_img"].reshape(h, w, 3)
        self._ambient = surf["amb_img"].reshape(h, w, 3)
        self._map = surf["maps"].reshape(h, w, 2)
        self._gt = self._truth(*surf["gt"])

    def _truth(self, *flat: np.ndarray) -> GroundTruth:
        """GroundTruth from the flat per-pixel (depth, column, row, lit, points)."""
        w, h = self.geometry.camera_size
        depth, col, row, lit, pts = flat
        return GroundTruth(*(a.reshape(h, w) for a in (depth, col, row, lit)), pts.reshape(h, w, 3))

    def _surface(self, shapes: list[Shape], shadows: bool = False) -> dict | None:
        """Per-pixel products of these shapes: frame buffers, ground truth (flat) and the camera hits.

        None when the camera sees none of them (unless `shadows`: then an empty layer). With
        `shadows`, also each lit pixel's distance, shadow-ray direction and projector coordinate
        (what the moving rig needs to shadow it later).
        """
        o = self.options
        w, h = self.geometry.camera_size
        wp, hp = self.geometry.projector_size
        npx = w * h
        d = self._rays
        t, sid, face = self._cast(shapes, np.zeros(3), d)
        hit = np.isfinite(t)
        if not hit.any():
            if not shadows:
                return None
            z3 = np.zeros((0, 3))
            return {
                "t": t,
                "sid": sid,
                "coef_img": np.zeros((npx, 3), np.float32),
                "amb_img": np.zeros((npx, 3), np.float32),
                "maps": np.full((npx, 2), -1, np.int16),
                "gt": (
                    np.zeros(npx, np.float32),
                    np.full(npx, np.nan, np.float32),
                    np.full(npx, np.nan, np.float32),
                    np.zeros(npx, bool),
                    np.zeros((npx, 3), np.float32),
                ),
                "lit_idx": np.zeros(0, np.int64),
                "lit_dist": np.zeros(0),
                "lit_neg_lvec": z3,
                "lit_xn": np.zeros((0, 2)),
            }
        idx = np.nonzero(hit)[0]
        X = d[idx] * t[idx, None]
        n = np.zeros((len(idx), 3))
        rho = np.zeros((len(idx), 3))
        shin = np.ones(len(idx))
        ks = np.zeros(len(idx))
        for i, s in enumerate(shapes):
            m = sid[idx] == i
            if not m.any():
                continue
            n[m] = s.normal(X[m], face[idx][m])
            rho[m] = self._albedo(s, idx[m], X[m], n[m], face[idx][m])
            ks[m] = s.material.specular
            shin[m] = s.material.shininess
        # normals toward the camera (planes are two-sided)
        flip = np.einsum("ij,ij->i", n, d[idx]) > 0
        n[flip] *= -1
        # projector: direction, distance, incidence, shadow, coordinates
        L = self._Cp - X
        dist = np.linalg.norm(L, axis=1)
        lvec = L / dist[:, None]
        cos_i = np.einsum("ij,ij->i", n, lvec)
        t_sh, _, _ = self._cast(shapes, self._Cp, -lvec)
        unshadowed = t_sh >= dist - (0.01 + 1e-5 * dist)
        Xp = affine3(X, self._R.T, after=self._T)
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = Xp[:, :2] / Xp[:, 2:3]
        lim = self._lim
        in_front = (Xp[:, 2] > 1.0) & np.all(np.abs(xn) < lim, axis=1)
        uvp = np.full((len(idx), 2), np.nan)
        if in_front.any():
            uvp[in_front] = project(X[in_front], self._Kp, self._distp, self._R, self._T)
        with np.errstate(invalid="ignore"):
            in_image = (uvp[:, 0] >= -0.5) & (uvp[:, 0] < wp - 0.5) & (uvp[:, 1] >= -0.5) & (uvp[:, 1] < hp - 0.5)
        lit = in_front & in_image & unshadowed & (cos_i > 1e-6)
        # shading and specular lobe (Blinn-Phong, halfway between projector and camera directions)
        falloff = (self._d_ref / dist) ** 2
        g = np.clip(cos_i, 0, None) * falloff if o.shading else np.ones(len(idx))
        coef = rho * g[:, None]
        if o.specular and np.any(ks > 0):
            hv = lvec - d[idx]
            hv /= np.linalg.norm(hv, axis=1, keepdims=True)
            lobe = ks * np.clip(np.einsum("ij,ij->i", n, hv), 0, None) ** shin * falloff
            coef += lobe[:, None]
        coef[~lit] = 0
        amb = rho * (o.ambient * np.asarray(o.ambient_color))[None, :]
        # per-pixel buffers for the frame path
        coef_img = np.zeros((npx, 3), np.float32)
        coef_img[idx] = coef * o.exposure
        amb_img = np.zeros((npx, 3), np.float32)
        amb_img[idx] = amb * o.exposure
        maps = np.full((npx, 2), -1, np.int16)
        lit_idx = idx[lit]
        maps[lit_idx] = np.floor(uvp[lit] + 0.5).astype(np.int16)
        # ground truth
        depth = np.zeros(npx, np.float32)
        depth[idx] = X[:, 2]
        pts = np.zeros((npx, 3), np.float32)
        pts[idx] = X
        col = np.full(npx, np.nan, np.float32)
        row = np.full(npx, np.nan, np.float32)
        col[lit_idx] = uvp[lit, 0]
        row[lit_idx] = uvp[lit, 1]
        lit_mask = np.zeros(npx, bool)
        lit_mask[lit_idx] = True
        out = {
            "t": t,
            "sid": sid,
            "coef_img": coef_img,
            "amb_img": amb_img,
            "maps": maps,
            "gt": (depth, col, row, lit_mask, pts),
            "lit_idx": lit_idx,
        }
        if shadows:
            out["lit_dist"] = dist[lit]
            out["lit_neg_lvec"] = -lvec[lit]
            out["lit_xn"] = xn[lit]
        return out

    def _albedo(self, s: Shape, pix: np.ndarray, X: np.ndarray, n: np.ndarray, face: np.ndarray) -> np.ndarray:
        ss = self.options.supersample
        if not s.antialias or ss <= 1:
            return s.albedo(X, face)
        # Average the texture over ss x ss sub-pixel rays meeting the surface's tangent plane:
        # sub-pixel ray directions from the local Jacobian of the (smooth) undistortion.
        w, h = self.geometry.camera_size
        rays = self._rays.reshape(h, w, 3)
        xy = rays[..., :2] / rays[..., 2:3]
        dx = np.gradient(xy, axis=1)
        dy = np.gradient(xy, axis=0)
        py, px = np.divmod(pix, w)
        base = xy[py, px]
        jx, jy = dx[py, px], dy[py, px]
        plane_d = np.einsum("ij,ij->i", n, X)

        def on_plane(sxy: np.ndarray) -> np.ndarray:
            dsub = np.concatenate([sxy, np.ones((len(sxy), 1))], axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                tt = plane_d / np.einsum("ij,ij->i", n, dsub)
            P = dsub * tt[:, None]
            bad = ~np.isfinite(tt) | (tt <= 0)
            P[bad] = X[bad]
            return P

        # texture coordinates are affine in the sub-pixel offset across one pixel (to ~1e-7 of
        # a pixel here), so three exact points give them all; then only the texture is sampled
        uv0 = s.uv(X, face)
        du = s.uv(on_plane(base + jx), face) - uv0
        dv = s.uv(on_plane(base + jy), face) - uv0
        offs = (np.arange(ss) + 0.5) / ss - 0.5
        acc = np.zeros((len(pix), 3))
        for oy in offs:
            for ox in offs:
                acc += s.texture.color(uv0 + ox * du + oy * dv, face, s.material.color)
        return acc / (ss * ss)

    # ------------------------------------------------------------------ frames
    def _make_lut(self) -> np.ndarray:
        x = np.arange(65536, dtype=np.float64) / 65535.0
        bits = self.options.bit_depth
        y = np.round(np.power(x, 1.0 / self.options.camera_gamma) * ((1 << bits) - 1))
        if bits == 12:  # a 12-bit sample in a 16-bit frame fills it from the top (drivers/camera/pixels.py)
            return (y.astype(np.uint16) << 4).astype(np.uint16)
        return y.astype(np.uint16 if bits == 16 else np.uint8)

    def prepare(self, pattern: np.ndarray) -> PreparedPattern:
        """Convert a projector image (Hp, Wp, 3) uint8 once; `render` accepts the result."""
        p = np.asarray(pattern)
        wp, hp = self.geometry.projector_size
        if p.ndim == 2:
            p = np.repeat(p[:, :, None], 3, axis=2)
        if p.shape != (hp, wp, 3) or p.dtype != np.uint8:
            raise InputError(
                f"virtual projector: pattern must be uint8 RGB {wp}x{hp} (shape ({hp}, {wp}, 3)), "
                f"found {p.dtype} shape {p.shape}"
            )
        o = self.options
        lin = cv2.LUT(np.ascontiguousarray(p), self._prep_lut.reshape(1, 256))
        if o.defocus_sigma_px > 0:
            cv2.GaussianBlur(lin, (0, 0), o.defocus_sigma_px, dst=lin, borderType=cv2.BORDER_REPLICATE)
        return PreparedPattern(np.ascontiguousarray(lin))

    def black(self) -> PreparedPattern:
        """The projector showing nothing (still leaking its black level)."""
        if self._black is None:
            wp, hp = self.geometry.projector_size
            self._black = self.prepare(np.zeros((hp, wp, 3), np.uint8))
        return self._black

    def render(self, pattern: np.ndarray | PreparedPattern | None) -> np.ndarray:
        """Camera image (H, W, 3) RGB uint8 (uint16 if 16-bit) of the scene under `pattern`.

        None means the projector is dark. Noise differs per call and is deterministic per seed.
        With motion, call n (from 0) shows the moving objects at frame n, and `ground_truth`
        is then that frame's.
        """
        prepared = pattern if isinstance(pattern, PreparedPattern) else None
        if prepared is None:
            prepared = self.black() if pattern is None else self.prepare(pattern)
        with self._lock:
            if self._moves and self.frame_index > 0:
                self._motion_step = self.frame_index
                if self._layer is not None:
                    self._compose()
                else:
                    self._precompute(self._current_shapes())
            self.frame_index += 1
            image = self._form(prepared.linear)
            if self._layer is not None and self.options.render_ahead:
                step = self.frame_index
                slot = (self._slot + 1) % len(self._layer.sets)
                self._ahead = _Ahead(self._layer, self._motion.shapes_at(self._base_shapes, step), step, slot)
            return image

    def _drop_ahead(self) -> None:
        ahead, self._ahead = self._ahead, None
        if ahead is not None:
            ahead.join(raise_error=False)

    def _form(self, light: np.ndarray) -> np.ndarray:
        o = self.options
        h, w = self._coef.shape[:2]
        if self._buf is None or self._buf.shape != (h, w, 3):
            self._buf = np.empty((h, w, 3), np.float32)
            self._buf2 = np.empty((h, w, 3), np.float32)
        light_to_linear(light, self._map, self._coef, self._ambient, self._mix32, self._buf)
        img = self._buf
        if o.psf_sigma_px > 0:
            cv2.GaussianBlur(img, (0, 0), o.psf_sigma_px * w / 640.0, dst=self._buf2, borderType=cv2.BORDER_REPLICATE)
            img = self._buf2
        out = np.empty((h, w, 3), self._lut.dtype)
        flat = img.reshape(-1)
        start = 0
        bank = self._noise_bank
        if bank is not None:
            start = int(self._rng.integers(0, len(bank) - flat.size))
        else:
            bank = np.zeros(1, np.float32)
        sensor(
            flat,
            bank,
            start,
            self._noise_bank is not None,
            1.0 / o.full_well,
            o.read_noise**2,
            self._lut,
            out.reshape(-1),
        )
        if self.mosaic is not None:
            out = sample_mosaic(out, self.mosaic)
        elif self.chroma is not None:
            out = subsample_chroma(out, self.chroma)
        return out


class _Ahead:
    """A moving rig's next frame, composed on a background thread into the other buffer set."""

    def __init__(self, layer: object, shapes: list[Shape], step: int, slot: int) -> None:
        self.step, self.slot = step, slot
        self.error: BaseException | None = None

        def run() -> None:
            try:
                layer.compose(shapes, slot)
            except BaseException as exc:  # handed to the render that needs this frame
                self.error = exc

        self.thread = threading.Thread(target=run, name="sim-render-ahead", daemon=True)
        self.thread.start()

    def join(self, raise_error: bool = True) -> None:
        self.thread.join()
        if self.error is not None and raise_error:
            raise self.error


def _finite(v: object) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) and bool(np.isfinite(v))


def _int_pair(v: object, key: str, where: str) -> tuple[int, int]:
    if isinstance(v, str):
        from core.patterns import parse_size

        return parse_size(v)
    if not (isinstance(v, list | tuple) and len(v) == 2 and all(isinstance(x, int | np.integer) for x in v)):
        raise InputError(f"{where}: '{key}' must be [w, h] whole numbers, found {v!r}")
    return int(v[0]), int(v[1])
