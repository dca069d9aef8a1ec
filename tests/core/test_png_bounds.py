"""An image's header is checked before its pixels are decoded: a small file declaring a huge image is refused."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from core.errors import InputError
from core.imageio import encode_png, read_rgb


def _png_header_only(path, w: int, h: int) -> None:
    """A PNG of a few bytes that declares a w x h RGB image (its pixel data cut short)."""
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    data = b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(ihdr)) + chunk + struct.pack(">I", zlib.crc32(chunk))
    path.write_bytes(data + b"\x00" * 64)


def test_a_png_declaring_20000_by_20000_pixels_is_refused_before_decoding(tmp_path):
    bomb = tmp_path / "bomb.png"
    _png_header_only(bomb, 20000, 20000)
    with pytest.raises(InputError, match=r"bomb.png: a 20000x20000 image is larger than any slscan reads"):
        read_rgb(bomb)


def test_ordinary_frames_still_read(tmp_path):
    img = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    (tmp_path / "f.png").write_bytes(encode_png(img))
    assert np.array_equal(read_rgb(tmp_path / "f.png"), img)
