"""`slscan.Decoder`: frame sets in pattern order -> scans (depth, points, colours, normals)."""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence

import numpy as np

from app.decode.pipeline import DEFAULT_DEPTH_RANGE_MM, EmptyResultWarning, FrameSetDecoder, average_frames_of
from core.calibration import Calibration
from core.errors import InputError
from core.pattern_export import read_patterns
from core.patterns import PatternSet
from slscan.dump import Dump
from slscan.frames import bgr_message, channel_order_matters, check_frames
from slscan.frameset import FrameSet
from slscan.scan import Scan

# A set that decodes to fewer valid pixels than this share is decoded once more with red and blue swapped: a BGR
# frame of an RGB pattern decodes to almost nothing (19 of 76,800 pixels on the virtual rig's plane).
BGR_CHECK_BELOW = 0.05


class Decoder:
    """Everything computed once per patterns, calibration and depth range; `decode(frames)` is the per-set call.

    patterns: a PatternSet (`dump.patterns`) or a pattern export folder (`slscan patterns --out DIR`).
    calibration: a Calibration or a calibration file. depth_range_mm: (near, far), the working volume: it picks
    between the repeated copies of a stripe sequence, so it should be the scene's, not "everything"; None takes
    (100, 5000), which for most rigs allows every copy and decodes nothing (a DepthRangeWarning says so).
    segmentation (two-shot): "runs" (default), "events" or "both"; motion (two-shot): "auto" decodes the newest
    frame alone where the scene moved since the frame before the set (FrameSet.previous), "off" never does.
    """

    def __init__(
        self,
        patterns: PatternSet | str | os.PathLike,
        calibration: Calibration | str | os.PathLike,
        depth_range_mm: tuple[float, float] | None = None,
        *,
        segmentation: str | None = None,
        motion: str = "auto",
        mosaic: str | None = None,
    ) -> None:
        if not isinstance(patterns, PatternSet):
            patterns = read_patterns(patterns)
        if calibration is None:
            raise InputError("Decoder: a calibration is needed to triangulate (Calibration or a calibration file)")
        if not isinstance(calibration, Calibration):
            calibration = Calibration.load(calibration)
        self.patterns = patterns
        self.calibration = calibration
        self.depth_range_mm = tuple(map(float, depth_range_mm or DEFAULT_DEPTH_RANGE_MM))
        meta = {**patterns.params, "scheme": patterns.scheme, "size": list(patterns.size), "images": patterns.names}
        self._decoder = FrameSetDecoder(
            patterns.scheme,
            meta,
            calibration,
            self.depth_range_mm,
            segmentation=segmentation,
            motion=motion,
            mosaic=mosaic,
        )
        self.mosaic = self._decoder.mosaic  # (checked: one of RGGB, GRBG, GBRG, BGGR, or None)
        self._check_bgr = channel_order_matters(patterns.images)

    @classmethod
    def for_dump(cls, dump: Dump, **options: object) -> Decoder:
        """The decoder of a dump: its patterns, calibration and depth range (options as for Decoder)."""
        if dump.calibration is None:
            raise InputError(
                f"{dump.path}: the dump has no calibration: use Decoder(dump.patterns, CALIBRATION_FILE, RANGE)"
            )
        options.setdefault("mosaic", dump.mosaic)
        return cls(dump.patterns, dump.calibration, dump.depth_range_mm, **options)  # type: ignore[arg-type]

    @property
    def scheme(self) -> str:
        return self.patterns.scheme

    @property
    def frames_per_set(self) -> int:
        return self._decoder.shots

    def decode(
        self,
        frames: Sequence[np.ndarray],
        *,
        newest: int | None = None,
        previous: np.ndarray | None = None,
        texture: np.ndarray | None = None,
        where: str = "frames",
    ) -> Scan:
        """A Scan of one frame set: RGB frames (H x W x 3, uint8 or uint16) in pattern order, frames[p] saw
        pattern p. newest (the pattern index of the frame taken last) and previous (the frame taken just before the
        set) enable two-shot motion handling; texture (a white-light frame) colours the scan, else the set's own
        frames do; a FrameSet from a dump carries all three. With the decoder's mosaic known, frames may be raw
        one-channel Bayer frames. Bad frames (number, shape, dtype, size, BGR channel order) are an InputError
        naming the frame."""
        if isinstance(frames, FrameSet):
            newest = frames.newest if newest is None else newest
            previous = frames.previous if previous is None else previous
            texture = frames.texture if texture is None else texture
        size, mosaic = self.calibration.camera_size, self.mosaic
        images = self._decoder.rgb(check_frames(frames, self.frames_per_set, size, where, mosaic))
        if previous is not None:
            previous = self._decoder.rgb_frame(check_frames([previous], 1, size, f"{where} (previous)", mosaic)[0])
        if texture is not None:
            texture = self._decoder.rgb_frame(check_frames([texture], 1, size, f"{where} (texture)", mosaic)[0])
        stripes, depth = self._decoder.stripes_and_depth(images, newest, previous)
        n_valid = int(stripes.valid.sum())
        if self._check_bgr and n_valid < BGR_CHECK_BELOW * stripes.valid.size:
            swapped = int(self._decoder.stripes([f[..., ::-1] for f in images]).valid.sum())
            if swapped > max(4 * n_valid, 0.01 * stripes.valid.size):
                raise InputError(bgr_message(where, n_valid, swapped))
        if n_valid == 0:
            warnings.warn(f"{where}: nothing decoded: {self._decoder.empty_reason()}", EmptyResultWarning, stacklevel=2)
        if texture is None:
            texture = images[0] if len(images) != 2 else average_frames_of(images[0], images[1])  # stripes cancel
        return Scan(
            depth,
            stripes.column,
            texture,
            self._decoder.triangulator.ray,
            frame_ids=getattr(frames, "frame_ids", ()),
            timestamp_ns=getattr(frames, "timestamp_ns", None),
        )
