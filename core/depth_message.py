"""The depth stream's message: one scan as a multipart message (docs/formats.md, "Depth stream").

    part 0: header, UTF-8 JSON (FORMAT, sequence, dropped, frame ids, timestamps, sizes, units, calibration digest)
    part 1: depth, H x W float32 little-endian, row-major, mm, 0 = none
    part 2: points, N x 3 float32 mm (camera frame), only when the header's "parts" lists "points"
    part 3: colours, N x 3 uint8 RGB, one per point, only with the points

The header says what follows, so a reader checks every size before it builds an array: a message that does not
match its header is refused with a one-line InputError (a stream is input from another process). Encoding and
decoding are pure (no sockets): the publisher (app/publisher.py) and slscan.Subscriber share them.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.errors import InputError

FORMAT = "slscan.depth/1"  # a reader refuses another format or major version
END = "end"  # header "kind" of the publisher's last message (no arrays): the stream ended cleanly
SCAN = "scan"
_MAX_HEADER = 64 * 1024


def calibration_digest(calibration: Any) -> str:
    """sha256 (hex) of the calibration's canonical bytes: the sizes and the model's numbers as little-endian float64
    in a fixed order, so the same calibration gives the same digest whichever file format or process it came from."""
    h = hashlib.sha256(b"slscan.calibration/1\0")
    for value in (
        calibration.camera_size,
        calibration.camera_matrix,
        calibration.camera_distortion,
        calibration.projector_size,
        calibration.projector_matrix,
        calibration.projector_distortion,
        calibration.R,
        calibration.T,
    ):
        h.update(np.ascontiguousarray(np.asarray(value, dtype="<f8")).tobytes())
    return h.hexdigest()


@dataclass
class DepthMessage:
    """One decoded message: the header (a dict, as sent) and its arrays (None where not sent)."""

    header: dict
    depth: np.ndarray | None
    points: np.ndarray | None = None
    colors: np.ndarray | None = None

    @property
    def is_end(self) -> bool:
        return self.header.get("kind") == END


def encode_scan(
    header: dict, depth: np.ndarray, points: np.ndarray | None = None, colors: np.ndarray | None = None
) -> list[Any]:
    """The message's parts: header fields given by the caller (sequence, dropped, frame ids, timestamps, digest) plus
    the ones this format fixes (sizes, dtype, units, parts). The arrays are passed as buffers, not copied."""
    depth = np.ascontiguousarray(depth, dtype="<f4")
    h, w = depth.shape
    parts = ["depth"]
    arrays: list[np.ndarray] = [depth]
    full = {**header, "format": FORMAT, "kind": SCAN, "width": w, "height": h, "dtype": "float32", "units": "mm"}
    full["none"] = 0
    if points is not None:
        points = np.ascontiguousarray(points, dtype="<f4").reshape(-1, 3)
        colors = np.ascontiguousarray(colors if colors is not None else np.zeros_like(points, np.uint8), np.uint8)
        if colors.shape != points.shape:
            raise ValueError(f"colours {colors.shape} do not match points {points.shape}")
        parts += ["points", "colors"]
        arrays += [points, colors]
        full["points"] = int(points.shape[0])
    full["parts"] = parts
    return [json.dumps(full, separators=(",", ":")).encode(), *(memoryview(a).cast("B") for a in arrays)]


def encode_end(header: dict) -> list[bytes]:
    """The last message of a stream: a header only (sequence = scans offered, dropped = the final count)."""
    return [json.dumps({**header, "format": FORMAT, "kind": END}, separators=(",", ":")).encode()]


def decode_message(parts: list[Any], where: str = "depth stream") -> DepthMessage:
    """A received message -> DepthMessage; arrays are read-only views of the received buffers (no copy)."""
    if not parts:
        raise InputError(f"{where}: empty message")
    raw = bytes(parts[0])
    if len(raw) > _MAX_HEADER:
        raise InputError(f"{where}: header of {len(raw)} bytes is not an slscan depth header")
    try:
        header = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError(f"{where}: the header is not JSON (not an slscan depth stream?)") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        found = header.get("format") if isinstance(header, dict) else None
        raise InputError(f"{where}: format {found!r}, expected {FORMAT!r}")
    if header.get("kind") == END:
        return DepthMessage(header, None)
    try:
        w, h = int(header["width"]), int(header["height"])
        names = list(header["parts"])
        n = int(header.get("points", 0))
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{where}: header lacks width, height or parts") from None
    if names not in (["depth"], ["depth", "points", "colors"]) or header.get("dtype") != "float32":
        raise InputError(f"{where}: parts {names} of dtype {header.get('dtype')!r} are not this format's")
    if len(parts) != 1 + len(names):
        raise InputError(f"{where}: {len(parts) - 1} array part(s), the header lists {len(names)}")
    shapes = {"depth": ((h, w), "<f4"), "points": ((n, 3), "<f4"), "colors": ((n, 3), np.uint8)}
    arrays: dict[str, np.ndarray] = {}
    for name, buf in zip(names, parts[1:], strict=True):
        shape, dtype = shapes[name]
        expected = int(np.prod(shape)) * np.dtype(dtype).itemsize
        mv = memoryview(buf)
        if mv.nbytes != expected:
            raise InputError(f"{where}: {name} has {mv.nbytes} bytes, the header says {shape} {np.dtype(dtype)}")
        arrays[name] = np.frombuffer(mv, dtype=dtype).reshape(shape)
    return DepthMessage(header, arrays["depth"], arrays.get("points"), arrays.get("colors"))
