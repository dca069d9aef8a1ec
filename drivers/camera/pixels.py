"""GenICam (PFNC) pixel formats -> RGB arrays. Pure: bytes in, arrays out, no device.

Output convention (the program's, docs/formats.md): RGB, shape (H, W, 3). 8-bit formats give
uint8. Deeper formats (10, 12, 14, 16 bits) give uint16 shifted left to fill 16 bits
(value << (16 - bits)), so 65535-ish means "clipped" whatever the sensor depth and a
decoder's thresholds do not depend on the camera model; the shift is exact and reversible.

Supported (`FORMATS`): Mono8/10/12/14/16, Mono10p/12p (PFNC LSB-first bit packing),
Mono10Packed/Mono12Packed (GigE Vision legacy packing), RGB8, BGR8, RGBa8, BGRa8,
RGB/BGR 10/12/16 (16-bit containers), Bayer RG/GB/GR/BG in 8, 10, 12, 16 bits and 10p/12p. A camera's
frames come from `to_frame`: Bayer formats as the raw mosaic (H, W), one sample per photosite, which the
decoder reconstructs along its stripes (app/decode/mosaic.py); `to_rgb` demosaics them with OpenCV (for
tools that want a photograph). Unpacked multi-byte samples are little-endian (PFNC).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


class PixelFormatError(ValueError):
    """A pixel format this module cannot convert, or a buffer that does not fit its format."""


@dataclass(frozen=True)
class PixelLayout:
    kind: str  # "mono", "rgb", "bgr", "rgba", "bgra", "bayer"
    bits: int  # significant bits per sample
    packing: str = "none"  # "none" (8 or 16-bit containers), "p" (PFNC LSB bit stream), "gige" (legacy *Packed)
    bayer: str = ""  # top-left 2x2 of the mosaic, row by row, e.g. "RGGB"

    @property
    def samples_per_pixel(self) -> int:
        return {"mono": 1, "bayer": 1, "rgb": 3, "bgr": 3, "rgba": 4, "bgra": 4}[self.kind]


def _formats() -> dict[str, PixelLayout]:
    f: dict[str, PixelLayout] = {}
    for bits in (8, 10, 12, 14, 16):
        f[f"Mono{bits}"] = PixelLayout("mono", bits)
    f["Mono10p"] = PixelLayout("mono", 10, "p")
    f["Mono12p"] = PixelLayout("mono", 12, "p")
    f["Mono10Packed"] = PixelLayout("mono", 10, "gige")
    f["Mono12Packed"] = PixelLayout("mono", 12, "gige")
    for bits in (8, 10, 12, 16):
        f[f"RGB{bits}"] = PixelLayout("rgb", bits)
        f[f"BGR{bits}"] = PixelLayout("bgr", bits)
    f["RGBa8"] = PixelLayout("rgba", 8)
    f["BGRa8"] = PixelLayout("bgra", 8)
    # GigE Vision 1.x names of the same layouts.
    f["RGB8Packed"] = f["RGB8"]
    f["BGR8Packed"] = f["BGR8"]
    f["RGBA8Packed"] = f["RGBa8"]
    f["BGRA8Packed"] = f["BGRa8"]
    for two, mosaic in (("RG", "RGGB"), ("GB", "GBRG"), ("GR", "GRBG"), ("BG", "BGGR")):
        for bits in (8, 10, 12, 16):
            f[f"Bayer{two}{bits}"] = PixelLayout("bayer", bits, bayer=mosaic)
        f[f"Bayer{two}10p"] = PixelLayout("bayer", 10, "p", mosaic)
        f[f"Bayer{two}12p"] = PixelLayout("bayer", 12, "p", mosaic)
    return f


FORMATS: dict[str, PixelLayout] = _formats()

# OpenCV's *RGGB* style codes name the sensor's top-left 2x2 (the older BG/RG names are shifted
# by one row and column; tests pin the mapping on synthetic mosaics).
_DEMOSAIC = {
    "RGGB": cv2.COLOR_BayerRGGB2RGB,
    "GBRG": cv2.COLOR_BayerGBRG2RGB,
    "GRBG": cv2.COLOR_BayerGRBG2RGB,
    "BGGR": cv2.COLOR_BayerBGGR2RGB,
}


def layout(fmt: str) -> PixelLayout:
    try:
        return FORMATS[fmt]
    except KeyError:
        raise PixelFormatError(
            f"pixel format {fmt!r} is not supported (supported: Mono8/10/12/16, RGB8, BGR8, RGBa8, Bayer*; "
            f"see drivers/camera/pixels.py)"
        ) from None


def is_supported(fmt: str) -> bool:
    return fmt in FORMATS


def camera_frame_dtype(fmt: object) -> np.dtype:
    """The dtype of the RGB frames a camera set to pixel format fmt delivers (to_rgb): uint16 for formats deeper
    than 8 bits, else (also for no format or an unknown one: the camera says so when it opens) uint8."""
    deep = isinstance(fmt, str) and is_supported(fmt) and FORMATS[fmt].bits > 8
    return np.dtype(np.uint16 if deep else np.uint8)


def camera_mosaic(fmt: object) -> str | None:
    """The Bayer mosaic (core/mosaic.py) of the raw frames a camera set to pixel format fmt delivers (to_frame),
    None for other formats, no format or an unknown one."""
    if isinstance(fmt, str) and is_supported(fmt) and FORMATS[fmt].kind == "bayer":
        return FORMATS[fmt].bayer
    return None


def line_bytes(fmt: str, width: int) -> int:
    """Bytes of one image line without padding (packed formats must end on a whole byte)."""
    lay = layout(fmt)
    n = width * lay.samples_per_pixel
    if lay.packing == "none":
        return n * (1 if lay.bits == 8 else 2)
    total_bits = n * (12 if lay.packing == "gige" else lay.bits)  # GigE packing stores 10-bit samples in 12 bits
    if total_bits % 8:
        raise PixelFormatError(f"{fmt}: a line of {width} pixels is not a whole number of bytes")
    return total_bits // 8


def _unpack_p(raw: np.ndarray, bits: int) -> np.ndarray:
    """PFNC 'p' packing: samples laid end to end, least significant bit first."""
    b = raw.astype(np.uint16)
    if bits == 12:  # 2 samples in 3 bytes
        b = b.reshape(-1, 3)
        out = np.empty((b.shape[0], 2), np.uint16)
        out[:, 0] = b[:, 0] | ((b[:, 1] & 0x0F) << 8)
        out[:, 1] = (b[:, 1] >> 4) | (b[:, 2] << 4)
        return out.ravel()
    if bits == 10:  # 4 samples in 5 bytes
        b = b.reshape(-1, 5)
        out = np.empty((b.shape[0], 4), np.uint16)
        out[:, 0] = b[:, 0] | ((b[:, 1] & 0x03) << 8)
        out[:, 1] = (b[:, 1] >> 2) | ((b[:, 2] & 0x0F) << 6)
        out[:, 2] = (b[:, 2] >> 4) | ((b[:, 3] & 0x3F) << 4)
        out[:, 3] = (b[:, 3] >> 6) | (b[:, 4] << 2)
        return out.ravel()
    raise PixelFormatError(f"no {bits}-bit 'p' unpacking")


def _unpack_gige(raw: np.ndarray, bits: int) -> np.ndarray:
    """GigE Vision Mono10Packed/Mono12Packed: 2 samples in 3 bytes, the middle byte holds both low parts."""
    b = raw.astype(np.uint16).reshape(-1, 3)
    out = np.empty((b.shape[0], 2), np.uint16)
    if bits == 12:
        out[:, 0] = (b[:, 0] << 4) | (b[:, 1] & 0x0F)
        out[:, 1] = (b[:, 2] << 4) | (b[:, 1] >> 4)
    else:
        out[:, 0] = (b[:, 0] << 2) | (b[:, 1] & 0x03)
        out[:, 1] = (b[:, 2] << 2) | ((b[:, 1] >> 4) & 0x03)
    return out.ravel()


def _group_samples(packing: str, bits: int) -> int:
    """Samples in one packing group (5 bytes for 10p, 3 bytes otherwise)."""
    return 4 if (packing == "p" and bits == 10) else 2


def samples(raw: bytes | np.ndarray, fmt: str, width: int, height: int, padding_x: int = 0) -> np.ndarray:
    """The raw sample plane, (H, W * samples_per_pixel), uint8 or uint16 as delivered (not shifted)."""
    lay = layout(fmt)
    if width <= 0 or height <= 0:
        raise PixelFormatError(f"{fmt}: bad image size {width}x{height}")
    buf = np.frombuffer(raw, np.uint8) if not isinstance(raw, np.ndarray) else raw.reshape(-1).view(np.uint8)
    n_line = width * lay.samples_per_pixel
    lb = line_bytes(fmt, width)
    stride = lb + padding_x
    need = stride * (height - 1) + lb
    if buf.size < need:
        raise PixelFormatError(f"{fmt} {width}x{height}: buffer holds {buf.size} bytes, needs {need}")
    if padding_x:
        lines = np.lib.stride_tricks.as_strided(buf, (height, lb), (stride, 1))
    else:
        lines = buf[: lb * height].reshape(height, lb)
    if lay.packing == "none":
        if lay.bits == 8:
            return lines
        return np.ascontiguousarray(lines).view("<u2").astype(np.uint16, copy=False).reshape(height, n_line)
    group_samples = _group_samples(lay.packing, lay.bits)
    if n_line % group_samples:
        raise PixelFormatError(f"{fmt}: width {width} is not a multiple of {group_samples} pixels")
    flat = np.ascontiguousarray(lines).reshape(-1)
    unpack = _unpack_p if lay.packing == "p" else _unpack_gige
    return unpack(flat, lay.bits).reshape(height, n_line)


def to_frame(raw: bytes | np.ndarray, fmt: str, width: int, height: int, padding_x: int = 0) -> np.ndarray:
    """A camera's frame of one image buffer, as a new array: Bayer formats give the raw mosaic (H, W) (uint8, or
    uint16 scaled to 16 bits; its mosaic is camera_mosaic(fmt)), every other format to_rgb's (H, W, 3)."""
    lay = layout(fmt)
    if lay.kind != "bayer":
        return to_rgb(raw, fmt, width, height, padding_x)
    s = samples(raw, fmt, width, height, padding_x)
    if lay.bits not in (8, 16):
        return s << np.uint16(16 - lay.bits)
    return s.copy() if lay.packing == "none" else s


def to_rgb(raw: bytes | np.ndarray, fmt: str, width: int, height: int, padding_x: int = 0) -> np.ndarray:
    """Convert one image buffer to a new (H, W, 3) RGB array (uint8, or uint16 scaled to 16 bits).

    The result never shares memory with `raw`, so the caller may hand the buffer back at once.
    """
    lay = layout(fmt)
    s = samples(raw, fmt, width, height, padding_x)
    if lay.bits not in (8, 16):
        s = s << np.uint16(16 - lay.bits)
    # OpenCV's colour conversions are several times faster than numpy fancy copies here.
    if lay.kind == "mono":
        return cv2.cvtColor(np.ascontiguousarray(s), cv2.COLOR_GRAY2RGB)
    if lay.kind == "bayer":
        return cv2.cvtColor(np.ascontiguousarray(s), _DEMOSAIC[lay.bayer])
    px = s.reshape(height, width, lay.samples_per_pixel)
    if lay.kind == "rgb":
        return px.copy()
    code = {"bgr": cv2.COLOR_BGR2RGB, "rgba": cv2.COLOR_RGBA2RGB, "bgra": cv2.COLOR_BGRA2RGB}[lay.kind]
    return cv2.cvtColor(np.ascontiguousarray(px), code)
