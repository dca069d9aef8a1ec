"""The one place that converts between the program's RGB arrays and OpenCV's BGR files."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from core.errors import InputError

# OpenCV logs its own WARN/ERROR lines for corrupt files; slscan reports those as one clear line itself.
cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)


def write_rgb(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an RGB (H, W, 3) or grey (H, W) uint8/uint16 image; PNG is lossless."""
    path = Path(path)
    arr = image[..., ::-1] if image.ndim == 3 else image
    try:
        ok = cv2.imwrite(str(path), np.ascontiguousarray(arr))
    except cv2.error as exc:
        raise InputError(f"{path}: cannot write image ({exc.msg.strip() if hasattr(exc, 'msg') else exc})") from None
    if not ok:
        raise InputError(f"{path}: cannot write image (check the folder exists and is writable)")


def read_rgb(path: str | os.PathLike, *, grey: bool = False) -> np.ndarray:
    """Read an image file as RGB (H, W, 3) — or (H, W) with grey=True — keeping 8 or 16 bits."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image file not found")
    flags = cv2.IMREAD_UNCHANGED
    img = cv2.imread(str(path), flags)
    if img is None:
        raise InputError(f"{path}: not a readable image (corrupt or truncated?)")
    if img.dtype not in (np.uint8, np.uint16, np.float32):
        raise InputError(f"{path}: unsupported pixel type {img.dtype}")
    if grey:
        if img.ndim == 3:
            raise InputError(f"{path}: expected a single-channel image, found {img.shape[2]} channels")
        return img
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    elif img.shape[2] == 4:
        img = img[:, :, :3]
    elif img.shape[2] != 3:
        raise InputError(f"{path}: expected an RGB image, found {img.shape[2]} channels")
    return np.ascontiguousarray(img[:, :, ::-1])


def write_float_tiff(path: str | os.PathLike, data: np.ndarray) -> None:
    """Write a single-channel float32 TIFF (depth in mm, projector coordinates)."""
    path = Path(path)
    if not cv2.imwrite(str(path), np.ascontiguousarray(data, dtype=np.float32)):
        raise InputError(f"{path}: cannot write TIFF (check the folder exists and is writable)")


def read_float_tiff(path: str | os.PathLike) -> np.ndarray:
    path = Path(path)
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(f"{path}: not a readable TIFF")
    if img.dtype != np.float32 or img.ndim != 2:
        raise InputError(f"{path}: expected a single-channel float32 TIFF, found {img.dtype} {img.shape}")
    return img


def encode_png(image: np.ndarray, params: tuple[int, ...] = ()) -> bytes:
    """Encode an RGB (H, W, 3) or grey (H, W) uint8/uint16 image as PNG bytes (OpenCV imwrite params)."""
    arr = image[..., ::-1] if image.ndim == 3 else image
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(arr), list(params))
    if not ok:
        raise InputError(f"cannot encode a {image.dtype} {image.shape} image as PNG")
    return buf.tobytes()
