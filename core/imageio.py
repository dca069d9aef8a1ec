"""The one place that converts between the program's RGB arrays and OpenCV's BGR files."""

from __future__ import annotations

import os
import resource
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


def read_rgb(path: str | os.PathLike, *, grey: bool = False, colour: bool = False) -> np.ndarray:
    """Read an image file as RGB (H, W, 3) — or (H, W) with grey=True — keeping 8 or 16 bits. With colour=True a
    single-channel file is refused rather than repeated into three equal channels (a camera frame)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image file not found")
    _check_png_size(path)
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
        if colour:
            raise InputError(
                f"{path}: a single-channel image where a colour frame is expected (a dump of raw Bayer frames names "
                "its mosaic in dump.yaml)"
            )
        img = np.repeat(img[:, :, None], 3, axis=2)
    elif img.shape[2] == 4:
        img = img[:, :, :3]
    elif img.shape[2] != 3:
        raise InputError(f"{path}: expected an RGB image, found {img.shape[2]} channels")
    return np.ascontiguousarray(img[:, :, ::-1])


MAX_PIXELS = 16384 * 16384  # the largest camera or pattern size slscan takes anywhere
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}  # by IHDR colour type: grey, RGB, palette, grey + alpha, RGBA


def _check_png_size(path: Path) -> None:
    """Refuse a PNG whose header asks for more memory than the machine has free, before decoding any pixel (a
    small file can declare a 20000 x 20000 image: decoding it would take gigabytes)."""
    try:
        with open(path, "rb") as f:
            head = f.read(26)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    if len(head) < 26 or head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        return  # not a PNG: cv2 reads it (or says it cannot)
    w, h = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    if w * h > MAX_PIXELS:
        raise InputError(f"{path}: a {w}x{h} image is larger than any slscan reads (at most 16384x16384 pixels)")
    depth, colour = head[24], head[25]
    need = w * h * PNG_CHANNELS.get(colour, 4) * (2 if depth > 8 else 1) * 2  # decoded, then its RGB copy
    free = _free_memory_bytes()
    if free is not None and need > free:
        raise InputError(
            f"{path}: a {w}x{h} image needs {need / 2**20:.0f} MB to decode, more than the {free / 2**20:.0f} MB free"
        )


def _free_memory_bytes() -> int | None:
    """Memory the process could still take: free physical memory, or less under an address-space limit
    (`ulimit -v`); None where the system says neither."""
    free = None
    try:
        page = os.sysconf("SC_PAGE_SIZE")
        free = os.sysconf("SC_AVPHYS_PAGES") * page
        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        if limit != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as f:  # (first field: the address space in use, in pages)
                used = int(f.read().split()[0]) * page
            free = min(free, max(limit - used, 0))
    except (AttributeError, ValueError, OSError):
        pass
    return free


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
