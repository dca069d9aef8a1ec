"""One frame set -> stripe map -> depth map and point cloud, for any scheme (used offline and live)."""

from __future__ import annotations

import threading
import warnings
from collections import deque
from dataclasses import dataclass

import numpy as np

from app.decode.colour import camera_gamma_of, linearisation
from app.decode.depth_range import check_depth_range, copy_columns
from app.decode.fast import average_frames
from app.decode.mosaic import NO_LEAKS, mosaic_leaks, to_rgb
from app.decode.motion import MotionParams, MotionRepair, check_motion_mode
from app.decode.response_inverse import ResponseInverse, response_inverse
from app.decode.stripemap import StripeMap
from app.decode.twoshot import SEGMENTATIONS, TwoShotDecoder
from app.schemes import get_scheme
from app.triangulate import PointCloud, Triangulator
from core.calibration import Calibration
from core.errors import InputError
from core.mosaic import mosaic_name

DEFAULT_DEPTH_RANGE_MM = (100.0, 5000.0)
# raw Bayer frames reconstructed to RGB kept by identity: live, each frame is in two pairs and reconstructed once
RGB_CACHE_FRAMES = 4


class EmptyResultWarning(UserWarning):
    """A frame set in which nothing could be decoded (black, empty or unlit scene)."""


class DepthRangeWarning(UserWarning):
    """A depth range that leaves the decoder nothing to find (app/decode/depth_range.py)."""


@dataclass
class DecodedSet:
    stripes: StripeMap
    depth: np.ndarray | None  # float32 mm, 0 = none; None without calibration
    cloud: PointCloud | None
    texture: np.ndarray  # RGB image to colour the cloud with


class FrameSetDecoder:
    """Everything precomputed once per (patterns, calibration, depth range)."""

    def __init__(
        self,
        scheme: str,
        pattern_meta: dict,
        calibration: Calibration | None = None,
        depth_range_mm: tuple[float, float] | None = None,
        segmentation: str | None = None,
        motion: str = "auto",
        mosaic: str | None = None,
        motion_params: MotionParams | None = None,
    ) -> None:
        """segmentation: two-shot stripes from code runs (default), zero crossings or both merged
        (TwoShotParams: both covers grazing surfaces a little better at twice the time). motion: "auto" decodes a
        two-shot pair's newest frame alone where the scene moved since the frame before the pair (app/decode/motion.py;
        the decode calls say which frame is newest and pass that previous frame), "off" always decodes the pair.
        motion_params: with motion "auto", when a pixel counts as moving and how it is thresholded (default
        MotionParams()).
        mosaic: the Bayer mosaic of raw (H, W) frames, which app/decode/mosaic.py reconstructs to RGB first; RGB
        frames decode as they are."""
        self.mosaic = mosaic_name(mosaic, "mosaic")
        # the last raw frames and their reconstructions: live, each frame is in two sliding pairs and is the
        # previous frame of a third set, so it is reconstructed once (entries hold the raw array: ids stay unique)
        self._rgb_cache: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=RGB_CACHE_FRAMES)
        self._rgb_lock = threading.Lock()
        if segmentation is not None and segmentation not in SEGMENTATIONS:
            raise InputError(f"segmentation {segmentation!r}: choose {', '.join(SEGMENTATIONS)}")
        self.kind = get_scheme(scheme)  # an unknown name is an InputError
        auto = check_motion_mode(motion, "scheme") == "auto" and self.kind.shots == 2
        self.motion = (motion_params or MotionParams()) if auto else None
        self._repairs: dict[np.dtype, MotionRepair] = {}  # per frame depth
        self.scheme = self.kind.name
        self.calibration = calibration
        self.triangulator = None
        self.depth_range_problem: str | None = None
        column_range = None
        proj_w = int(pattern_meta["size"][0])
        mixing = None
        gamma = 1.0
        if calibration is not None:
            if tuple(calibration.projector_size) != tuple(pattern_meta["size"]):
                raise InputError(
                    f"calibration projector_size {calibration.projector_size} differs from the patterns' size "
                    f"{tuple(pattern_meta['size'])}"
                )
            self.triangulator = Triangulator(calibration, depth_range_mm or DEFAULT_DEPTH_RANGE_MM)
            column_range = self.triangulator.column_range
            # (a range that misses the projector's image everywhere is an InputError; one that allows every copy of
            # the sequence decodes nothing, said here once and again with every empty result)
            self.depth_range_problem = check_depth_range(
                *column_range, proj_w, copy_columns(pattern_meta), self.triangulator.depth_range_mm
            )
            if self.depth_range_problem is not None:
                warnings.warn(self.depth_range_problem, DepthRangeWarning, stacklevel=2)
            mixing = calibration.color_mixing
            gamma = camera_gamma_of(calibration)
        # a raw mosaic's lacking channel is filled consistently with the unmixing the decoder applies, in the linear
        # light of the camera response it linearises with (per frame depth: response)
        self.leaks = mosaic_leaks(mixing) if self.mosaic is not None else NO_LEAKS
        self.camera_gamma = gamma
        self._responses: dict[np.dtype, ResponseInverse] = {}
        self.decoder = self.kind.make_decoder(pattern_meta, proj_w, mixing, column_range, segmentation, gamma)
        if isinstance(self.decoder, TwoShotDecoder):  # the lacking channel's signs from the G edges, in its row loop
            self.decoder.mosaic = self.mosaic
        self.shots = self.decoder.shots

    def empty_reason(self) -> str:
        """Why a frame set may have decoded to nothing, as the end of a one-line message."""
        if self.depth_range_problem is not None:
            return self.depth_range_problem
        if self.triangulator is None:
            return "a dark, empty or unlit scene"
        near, far = self.triangulator.depth_range_mm
        return f"a dark, empty or unlit scene, or no surface inside the depth range {near:g}-{far:g} mm"

    def check_frames(self, frames: list[np.ndarray], where: str = "frame set") -> None:
        if len(frames) != self.shots:
            raise InputError(f"{where}: scheme {self.scheme} needs {self.shots} frames per set, got {len(frames)}")
        shape = frames[0].shape
        for f in frames:
            if f.shape != shape:
                raise InputError(
                    f"{where}: frames of one set differ in size ({shape[1]}x{shape[0]} vs {f.shape[1]}x{f.shape[0]})"
                )
        if self.calibration is not None:
            self.calibration.check_camera_size(shape[1], shape[0], where)

    def stripes_and_depth(
        self, frames: list[np.ndarray], newest: int | None = None, previous: np.ndarray | None = None
    ) -> tuple[StripeMap, np.ndarray | None]:
        """The stripe map of a frame set (in pattern order, sizes checked by the caller) and, with a calibration,
        its depth map: the per-frame work of decode() without the texture and the point cloud. The two-shot
        decoder triangulates row by row in its own pass where the triangulator has the closed form. newest: the
        index in frames of the frame taken last; previous: the frame taken just before the set (it saw the newest
        frame's pattern): with both and motion "auto", a two-shot pair decodes its newest frame where the scene moved
        (the stripe map's info "moving" = the share of such pixels)."""
        frames, moving = self.repaired(frames, newest, previous)
        depth = None
        geometry = self.triangulator.moebius_geometry if self.triangulator is not None else None
        if self.kind.depth_in_decode and geometry is not None:
            sm, depth = self.decoder.decode_depth(frames[0], frames[1], geometry)
        else:
            sm = self.kind.stripes(self.decoder, frames)
        if depth is None and self.triangulator is not None:
            depth = self.triangulator.depth(sm.column)
        return _noting_motion(sm, moving), depth

    def stripes(
        self, frames: list[np.ndarray], newest: int | None = None, previous: np.ndarray | None = None
    ) -> StripeMap:
        """The stripe map alone of a frame set in pattern order (no checks, no triangulation); newest, previous:
        see stripes_and_depth."""
        frames, moving = self.repaired(list(frames), newest, previous)
        return _noting_motion(self.kind.stripes(self.decoder, frames), moving)

    def rgb(self, frames: list[np.ndarray] | tuple[np.ndarray, ...]) -> list[np.ndarray]:
        """frames as RGB: raw Bayer frames reconstructed along the stripes (app/decode/mosaic.py), RGB as they are."""
        return [self.rgb_frame(f) for f in frames]

    def rgb_frame(self, frame: np.ndarray | None) -> np.ndarray | None:
        """One frame as RGB (rgb); None stays None."""
        if frame is None or frame.ndim == 3:
            return frame
        if self.mosaic is None:
            raise InputError(
                f"a one-channel {frame.shape[1]}x{frame.shape[0]} frame: the camera's Bayer mosaic is not known"
            )
        with self._rgb_lock:
            for raw, rgb in self._rgb_cache:
                if raw is frame:
                    return rgb
        rgb = to_rgb(frame, self.mosaic, self.leaks, self.response(frame.dtype))
        with self._rgb_lock:
            self._rgb_cache.append((frame, rgb))
        return rgb

    def response(self, dtype: np.dtype) -> ResponseInverse:
        """The camera response the decoder linearises frames of this depth with, and its inverse (the two-shot
        decoder's tables, else the calibration's gamma), built once per depth."""
        dtype = np.dtype(dtype)
        with self._rgb_lock:
            found = self._responses.get(dtype)
        if found is None:
            if isinstance(self.decoder, TwoShotDecoder):
                found = self.decoder.inverse(dtype)  # (the one its row loop moves a raw fill's codes with)
            else:
                found = response_inverse(linearisation(65536 if dtype == np.uint16 else 256, self.camera_gamma)[0])
            with self._rgb_lock:
                self._responses[dtype] = found
        return found

    def repaired(
        self, frames: list[np.ndarray], newest: int | None, previous: np.ndarray | None
    ) -> tuple[list[np.ndarray], float | None]:
        """(frames with the older frame of a two-shot pair repaired where the scene moved, the share of moving
        pixels), or the frames as they are and None without motion, a newest index or a previous frame; raw Bayer
        frames come back reconstructed to RGB (rgb)."""
        frames, previous = self.rgb(frames), self.rgb_frame(previous)
        if self.motion is None or newest is None or previous is None:
            return frames, None
        if newest not in (0, 1):
            raise InputError(f"newest frame index {newest} of a two-shot pair: must be 0 or 1")
        older = 1 - newest
        dtype = np.dtype(frames[newest].dtype)
        if dtype not in self._repairs:
            self._repairs[dtype] = MotionRepair(self.decoder.luts(dtype), self.decoder.channels, self.motion)
        fixed, n = self._repairs[dtype](frames[newest], frames[older], previous)
        out = list(frames)
        out[older] = fixed
        return out, n / max(1, frames[newest].shape[0] * frames[newest].shape[1])

    def decode(
        self,
        frames: list[np.ndarray],
        where: str = "frame set",
        newest: int | None = None,
        previous: np.ndarray | None = None,
        texture: np.ndarray | None = None,
    ) -> DecodedSet:
        """frames in pattern order (frames[p] saw pattern p); newest, previous: see stripes_and_depth (without them
        the order in time does not matter). texture: a white-light frame (the object's own colour) to colour the
        cloud with; without it the set's own frames colour it."""
        self.check_frames(frames, where)
        if previous is not None:
            self.check_frames([previous] * self.shots, f"{where} (previous frame)")
        if texture is not None:
            self.check_frames([texture] * self.shots, f"{where} (texture frame)")
        frames, previous, texture = self.rgb(frames), self.rgb_frame(previous), self.rgb_frame(texture)
        sm, depth = self.stripes_and_depth(frames, newest, previous)
        if texture is None:  # two-shot: a pair's mean, where the stripes cancel
            texture = average_frames_of(frames[0], frames[1]) if self.kind.shots == 2 else frames[0]
        if not sm.valid.any():
            warnings.warn(f"{where}: nothing decoded: {self.empty_reason()}", EmptyResultWarning, stacklevel=2)
        cloud = None
        if self.triangulator is not None:
            cloud = self.triangulator.points(depth, texture)
        return DecodedSet(sm, depth, cloud, texture)


def _noting_motion(sm: StripeMap, moving: float | None) -> StripeMap:
    """sm with its info "moving" (the share of pixels decoded from the newest frame alone) where motion was handled."""
    if moving is not None:
        sm.info["moving"] = moving
    return sm


def average_frames_of(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(a + b) // 2 of two frames of one shape and unsigned integer dtype, without overflow (one compiled pass)."""
    out = np.empty_like(a)
    same = a.shape == b.shape and a.dtype == b.dtype
    if same and a.flags.c_contiguous and b.flags.c_contiguous and a.dtype.kind == "u":
        average_frames(a, b, out)
    else:
        out[...] = ((a.astype(np.uint32) + b) // 2).astype(a.dtype)
    return out
