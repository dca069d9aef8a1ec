"""What the decoder accepts as frames, checked with a one-line error naming the frame and what to do."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from core.errors import InputError

DTYPES = (np.uint8, np.uint16)


def check_frames(
    frames: Sequence[np.ndarray],
    shots: int,
    camera_size: tuple[int, int],
    where: str = "frames",
    mosaic: str | None = None,
) -> list[np.ndarray]:
    """The frames as C-contiguous arrays, or InputError: their number, array type, shape (H x W x 3 RGB, or H x W
    raw Bayer frames where the camera's mosaic is known), dtype (uint8 or uint16, one for all) and size (the
    calibration's camera_size)."""
    if isinstance(frames, np.ndarray) and frames.ndim == 3:
        raise InputError(f"{where}: one image given; pass a list of {shots} frame(s) in pattern order")
    try:
        frames = list(frames)
    except TypeError:
        raise InputError(f"{where}: expected a list of {shots} frame(s), got {type(frames).__name__}") from None
    if len(frames) != shots:
        raise InputError(f"{where}: this scheme needs {shots} frame(s) per set in pattern order, got {len(frames)}")
    out = []
    for i, f in enumerate(frames):
        name = f"{where}[{i}]"
        if not isinstance(f, np.ndarray):
            raise InputError(f"{name} is a {type(f).__name__}, not a numpy array (H x W x 3 RGB)")
        if f.ndim == 2:
            if mosaic is None:
                raise InputError(
                    f"{name} is a grey image ({f.shape[1]}x{f.shape[0]}): the decoder needs RGB H x W x 3, or a raw "
                    "Bayer frame with the camera's mosaic named (Decoder(..., mosaic='RGGB'))"
                )
        elif f.ndim != 3 or f.shape[2] not in (3, 4):
            raise InputError(f"{name} has shape {f.shape}: expected H x W x 3 (RGB)")
        elif f.shape[2] == 4:
            raise InputError(f"{name} has 4 channels: pass the three colour channels in RGB order (frame[..., :3])")
        if f.dtype not in DTYPES:
            raise InputError(f"{name} has dtype {f.dtype}: expected uint8 or uint16 camera values, not scaled")
        if f.dtype != frames[0].dtype:
            raise InputError(f"{name} is {f.dtype} but {where}[0] is {frames[0].dtype}: one dtype for a set")
        if (f.shape[1], f.shape[0]) != tuple(camera_size):
            raise InputError(
                f"{name} is {f.shape[1]}x{f.shape[0]} but the calibration's camera_size is "
                f"{camera_size[0]}x{camera_size[1]}"
            )
        out.append(np.ascontiguousarray(f))
    return out


def channel_order_matters(pattern_images: Sequence[np.ndarray]) -> bool:
    """False when every pattern lights red and blue alike (Gray code's white and black): then a BGR frame decodes
    as its RGB copy would, and needs no check."""
    return any(not np.array_equal(img[..., 0], img[..., 2]) for img in pattern_images)


def bgr_message(where: str, valid_as_given: int, valid_swapped: int) -> str:
    return (
        f"{where}: the frames look BGR (the order cv2.imread returns), not RGB: swapped to RGB they decode "
        f"{valid_swapped} pixels, as given {valid_as_given}; convert them with frame[..., ::-1] "
        "(or cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))"
    )
