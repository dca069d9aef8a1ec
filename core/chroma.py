"""Colour subsampled across the image's rows: what webcams deliver (YUYV 4:2:2, MJPEG 4:2:0).

Such a camera keeps full-resolution luma but one chroma sample per 2 pixels of a row (4:2:2; and per 2 rows,
4:2:0), so colour changes faster than every 2 camera pixels are lost, and the projected stripes are vertical:
their colour changes across the row. Pure: names, the formats that carry them, and an emulation.
"""

from __future__ import annotations

import cv2
import numpy as np

from core.errors import InputError

# chroma name -> (horizontal, vertical) subsampling
CHROMA = {"4:2:2": (2, 1), "4:2:0": (2, 2)}

# V4L2 FOURCCs (and the names slscan's V4L2 option takes) whose colour is subsampled
FOURCC_CHROMA = {
    "YUYV": "4:2:2",
    "YUY2": "4:2:2",
    "UYVY": "4:2:2",
    "YVYU": "4:2:2",
    "VYUY": "4:2:2",
    "NV16": "4:2:2",
    "MJPG": "4:2:0",  # (webcams' MJPEG is 4:2:0 in practice; some send 4:2:2, which carries no more)
    "JPEG": "4:2:0",
    "NV12": "4:2:0",
    "NV21": "4:2:0",
    "YU12": "4:2:0",
    "YV12": "4:2:0",
    "I420": "4:2:0",
}


def chroma_name(value: object, where: str) -> str | None:
    """A chroma setting as "4:2:2" or "4:2:0" (also "422", "420"), None for full colour ("4:4:4", false, None);
    anything else is a one-line InputError naming where."""
    if value is None or value is False:
        return None
    text = str(value).strip()
    if text in ("4:4:4", "444"):
        return None
    if text in CHROMA:
        return text
    if text in ("422", "420"):
        return f"{text[0]}:{text[1]}:{text[2]}"
    raise InputError(f"{where}: {value!r} is not a chroma subsampling (choose 4:2:2, 4:2:0 or 4:4:4)")


def chroma_of_fourcc(fourcc: object) -> str | None:
    """The chroma subsampling of a V4L2 pixel format, None for full colour or an unknown format."""
    return FOURCC_CHROMA.get(str(fourcc).upper()) if fourcc else None


def subsample_chroma(image: np.ndarray, chroma: str) -> np.ndarray:
    """An RGB frame (uint8 or uint16) as a camera with this chroma delivers it after its decoder: BT.601 YCbCr,
    chroma averaged over each 2 (4:2:2) or 2x2 (4:2:0) block of pixels, upsampled again (4:2:2 by repetition,
    as OpenCV's YUYV conversion; 4:2:0 bilinearly, as libjpeg's default), back to RGB."""
    fx, fy = CHROMA[chroma]
    h, w = image.shape[:2]
    top = float(np.iinfo(image.dtype).max)
    ycc = cv2.cvtColor(image.astype(np.float32) / top, cv2.COLOR_RGB2YCrCb)
    c = ycc[..., 1:]
    hh, ww = h - h % fy, w - w % fx
    small = c[:hh, :ww].reshape(hh // fy, fy, ww // fx, fx, 2).mean(axis=(1, 3))
    interp = cv2.INTER_NEAREST if fy == 1 else cv2.INTER_LINEAR
    up = cv2.resize(small, (ww, hh), interpolation=interp)
    c[:hh, :ww] = up
    rgb = cv2.cvtColor(ycc, cv2.COLOR_YCrCb2RGB)
    return np.clip(np.round(rgb * top), 0, top).astype(image.dtype)
