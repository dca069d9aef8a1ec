"""Pixel-format conversion on synthetic buffers, every format, against independent reference encoders."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.camera import pixels
from drivers.camera.pixels import FORMATS, PixelFormatError, to_rgb

RNG = np.random.default_rng(5)
W, H = 8, 6


def encode_p(values: np.ndarray, bits: int) -> bytes:
    """PFNC 'p' packing, written bit by bit: each sample LSB first, bytes filled LSB first."""
    stream = [(int(v) >> i) & 1 for v in values.ravel() for i in range(bits)]
    out = bytearray()
    for i in range(0, len(stream), 8):
        out.append(sum(bit << j for j, bit in enumerate(stream[i : i + 8])))
    return bytes(out)


def encode_gige(values: np.ndarray, bits: int) -> bytes:
    """GigE Vision Mono10Packed / Mono12Packed, from the spec's byte diagram."""
    out = bytearray()
    v = [int(x) for x in values.ravel()]
    for a, b in zip(v[0::2], v[1::2], strict=True):
        if bits == 12:
            out += bytes([a >> 4, (a & 0xF) | ((b & 0xF) << 4), b >> 4])
        else:
            out += bytes([a >> 2, (a & 0x3) | ((b & 0x3) << 4), b >> 2])
    return bytes(out)


def encode(values: np.ndarray, fmt: str) -> bytes:
    """Samples (H, W*spp) -> the raw bytes of `fmt`, line after line."""
    lay = FORMATS[fmt]
    if lay.packing == "p":
        return encode_p(values, lay.bits)
    if lay.packing == "gige":
        return encode_gige(values, lay.bits)
    if lay.bits == 8:
        return values.astype(np.uint8).tobytes()
    return values.astype("<u2").tobytes()


def true_samples(fmt: str, width: int = W, height: int = H) -> np.ndarray:
    lay = FORMATS[fmt]
    return RNG.integers(0, 2**lay.bits, size=(height, width * lay.samples_per_pixel))


def scaled(v: np.ndarray, bits: int) -> np.ndarray:
    return v if bits == 8 else (v << (16 - bits))


NON_BAYER = [f for f, lay in FORMATS.items() if lay.kind != "bayer"]
BAYER = [f for f, lay in FORMATS.items() if lay.kind == "bayer"]


@pytest.mark.parametrize("fmt", NON_BAYER)
def test_mono_and_colour_formats_round_trip(fmt):
    lay = FORMATS[fmt]
    v = true_samples(fmt)
    rgb = to_rgb(encode(v, fmt), fmt, W, H)
    assert rgb.shape == (H, W, 3)
    assert rgb.dtype == (np.uint8 if lay.bits == 8 else np.uint16)
    assert pixels.camera_frame_dtype(fmt) == rgb.dtype  # (what the live session compiles its decoder for)
    s = scaled(v, lay.bits).reshape(H, W, lay.samples_per_pixel)
    expect = {
        "mono": lambda: np.repeat(s, 3, axis=2),
        "rgb": lambda: s,
        "bgr": lambda: s[:, :, ::-1],
        "rgba": lambda: s[:, :, :3],
        "bgra": lambda: s[:, :, [2, 1, 0]],
    }[lay.kind]()
    np.testing.assert_array_equal(rgb, expect)


@pytest.mark.parametrize("fmt", BAYER)
def test_bayer_uniform_colour_demosaics_to_that_colour(fmt):
    """A flat (R, G, B) field mosaiced in the format's layout comes back as (R, G, B) everywhere inside."""
    lay = FORMATS[fmt]
    colour = {"R": 900, "G": 500, "B": 100} if lay.bits > 8 else {"R": 200, "G": 120, "B": 30}
    w, h = 16, 12
    mosaic = np.empty((h, w), np.int64)
    for dy in (0, 1):
        for dx in (0, 1):
            mosaic[dy::2, dx::2] = colour[lay.bayer[2 * dy + dx]]
    rgb = to_rgb(encode(mosaic, fmt), fmt, w, h)
    want = scaled(np.array([colour["R"], colour["G"], colour["B"]]), lay.bits)
    inner = rgb[2:-2, 2:-2].reshape(-1, 3)
    assert (inner == want).all(), f"{fmt}: got {np.unique(inner, axis=0)[:3]}, want {want}"


@pytest.mark.parametrize("fmt", BAYER)
def test_bayer_frames_are_the_raw_mosaic_with_its_order(fmt):
    """A camera's frame of a Bayer format is the sample plane itself (scaled to 16 bits), its mosaic named."""
    lay = FORMATS[fmt]
    w, h = 16, 12
    mosaic = RNG.integers(0, 1 << lay.bits, (h, w))
    frame = pixels.to_frame(encode(mosaic, fmt), fmt, w, h)
    assert frame.shape == (h, w) and frame.dtype == (np.uint8 if lay.bits == 8 else np.uint16)
    assert np.array_equal(frame, scaled(mosaic, lay.bits))
    assert pixels.camera_mosaic(fmt) == lay.bayer
    assert pixels.camera_mosaic("RGB8") is None and pixels.to_frame(bytes(w * h * 3), "RGB8", w, h).shape == (h, w, 3)


def test_bayer_layouts_are_distinguished():
    """The four mosaics of one field decode differently unless told the right layout (no silent swap)."""
    mosaic = np.empty((12, 16), np.uint8)
    for dy in (0, 1):
        for dx in (0, 1):
            mosaic[dy::2, dx::2] = {"R": 200, "G": 120, "B": 30}["RGGB"[2 * dy + dx]]
    raw = mosaic.tobytes()
    centre = {f: tuple(to_rgb(raw, f, 16, 12)[6, 8]) for f in ("BayerRG8", "BayerBG8", "BayerGR8", "BayerGB8")}
    assert centre["BayerRG8"] == (200, 120, 30)
    assert centre["BayerBG8"] == (30, 120, 200)  # R and B swapped when the layout is wrong
    assert centre["BayerGR8"] != (200, 120, 30) and centre["BayerGB8"] != (200, 120, 30)


@pytest.mark.parametrize("fmt", ["Mono8", "Mono12", "RGB8", "RGBa8", "BayerGB8", "Mono12p", "Mono12Packed"])
def test_line_padding_is_skipped(fmt):
    lay = FORMATS[fmt]
    v = true_samples(fmt)
    lines = [encode(v[y : y + 1], fmt) for y in range(H)]
    pad = 5
    raw = b"".join(line + bytes([0xAB] * pad) for line in lines)[:-pad]  # no padding needed after the last line
    np.testing.assert_array_equal(to_rgb(raw, fmt, W, H, padding_x=pad), to_rgb(b"".join(lines), fmt, W, H))
    assert pixels.line_bytes(fmt, W) == len(lines[0])
    assert lay.bits >= 8


def test_result_does_not_share_the_buffer():
    """The driver queues the buffer back right after conversion: the frame must own its pixels."""
    for fmt in NON_BAYER + BAYER:
        raw = np.frombuffer(encode(true_samples(fmt), fmt), np.uint8).copy()
        rgb = to_rgb(raw, fmt, W, H)
        assert not np.shares_memory(rgb, raw), fmt
        before = rgb.copy()
        raw[:] = 0
        np.testing.assert_array_equal(rgb, before)


def test_short_buffer_and_unknown_format_are_clear_errors():
    with pytest.raises(PixelFormatError, match=r"Mono16 8x6: buffer holds 10 bytes, needs 96"):
        to_rgb(bytes(10), "Mono16", W, H)
    with pytest.raises(PixelFormatError, match=r"'YCbCr422_8' is not supported"):
        to_rgb(bytes(1000), "YCbCr422_8", W, H)
    with pytest.raises(PixelFormatError, match="6 pixels is not a whole number of bytes"):
        to_rgb(bytes(1000), "Mono10p", 6, 2)
    assert not pixels.is_supported("YUV422Packed") and pixels.is_supported("BayerRG12p")


def test_real_sized_frame_from_numpy_view():
    """A 1280x1024 Mono12p frame as the driver sees it (uint8 view of a larger buffer)."""
    w, h = 1280, 1024
    v = RNG.integers(0, 4096, size=(h, w))
    raw = np.frombuffer(encode_p(v[:2], 12) + bytes((h - 2) * w * 3 // 2), np.uint8)
    big = np.concatenate([raw, np.zeros(64, np.uint8)])
    rgb = to_rgb(big, "Mono12p", w, h)
    np.testing.assert_array_equal(rgb[:2, :, 1], v[:2] << 4)
    assert (rgb[2:] == 0).all()


def test_frame_dtype_of_bayer_no_and_unknown_formats():
    for fmt in BAYER:
        lay = FORMATS[fmt]
        raw = np.zeros(pixels.line_bytes(fmt, W) * H, np.uint8)
        assert (
            pixels.camera_frame_dtype(fmt) == to_rgb(raw, fmt, W, H).dtype == (np.uint8 if lay.bits == 8 else np.uint16)
        )
    assert pixels.camera_frame_dtype(None) == pixels.camera_frame_dtype("NoSuchFormat") == np.uint8
