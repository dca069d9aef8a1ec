"""Bayer colour-filter mosaics: their names and the one-channel frames a single-chip camera delivers.

A mosaic is named by the colours of the sensor's top-left 2x2 photosites, row by row (`RGGB`: R at
(0, 0), G at (0, 1) and (1, 0), B at (1, 1)), as GenICam's `BayerRG*` formats and OpenCV's `*RGGB*` codes
do. A raw frame is (H, W), one sample per photosite, uint8 or uint16 (deeper samples shifted to fill 16 bits,
as every frame of the program). Pure: no device, no decoder.
"""

from __future__ import annotations

import numpy as np

from core.errors import InputError

MOSAICS = ("RGGB", "GRBG", "GBRG", "BGGR")
CHANNEL = {"R": 0, "G": 1, "B": 2}


def mosaic_name(value: object, where: str) -> str | None:
    """A mosaic setting as its canonical name, or None for a camera with one colour per pixel (3-CCD, RGB).

    Takes a name of MOSAICS (any case), true (RGGB: the meaning of the virtual rig's former `bayer: true`),
    false or None. where names the field in the one-line error for anything else."""
    if value is None or value is False:
        return None
    if value is True:
        return "RGGB"
    if isinstance(value, str) and value.upper() in MOSAICS:
        return value.upper()
    raise InputError(f"{where}: {value!r} is not a Bayer mosaic (choose {', '.join(MOSAICS)}, or false)")


def site_codes(mosaic: str) -> np.ndarray:
    """The channel index (0 R, 1 G, 2 B) of each site of the 2x2 tile, [row parity, column parity] (int64)."""
    return np.array([[CHANNEL[mosaic[2 * dy + dx]] for dx in (0, 1)] for dy in (0, 1)], np.int64)


def sample_mosaic(image: np.ndarray, mosaic: str) -> np.ndarray:
    """The raw frame a sensor with this mosaic records of an RGB image (H, W, 3): each site keeps its channel."""
    codes = site_codes(mosaic)
    raw = np.empty(image.shape[:2], image.dtype)
    for dy in (0, 1):
        for dx in (0, 1):
            raw[dy::2, dx::2] = image[dy::2, dx::2, codes[dy, dx]]
    return raw
