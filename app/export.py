"""Writing results: depth TIFF, binary PLY point cloud, stripe pseudo-colour PNG, depth previews."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from app.triangulate import PointCloud
from core.errors import InputError
from core.imageio import write_float_tiff, write_rgb


def write_depth_tiff(path: str | os.PathLike, depth: np.ndarray) -> None:
    """float32 Z in mm, 0 = no value."""
    write_float_tiff(path, depth.astype(np.float32, copy=False))


def write_ply(path: str | os.PathLike, cloud: PointCloud) -> None:
    """Binary little-endian PLY: x y z float32, red green blue uchar."""
    n = len(cloud.xyz)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment slscan point cloud, camera frame, mm\n"
        f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    rec = np.empty(n, dtype=[("xyz", "<f4", 3), ("rgb", "u1", 3)])
    rec["xyz"] = cloud.xyz
    rec["rgb"] = cloud.rgb
    try:
        with open(path, "wb") as f:
            f.write(header.encode("ascii"))
            f.write(rec.tobytes())
    except OSError as exc:
        raise InputError(f"{path}: cannot write PLY ({exc.strerror})") from None


def read_ply(path: str | os.PathLike) -> PointCloud:
    """Read back what `write_ply` writes (binary little-endian, x y z float + r g b uchar)."""
    path = Path(path)
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise InputError(f"{path}: not a PLY file")
    header = data[:end].decode("ascii", errors="replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise InputError(f"{path}: only binary little-endian PLY is read")
    n = next((int(line.split()[2]) for line in header if line.startswith("element vertex")), None)
    if n is None:
        raise InputError(f"{path}: no vertex element")
    rec = np.frombuffer(data, dtype=[("xyz", "<f4", 3), ("rgb", "u1", 3)], count=n, offset=end + len("end_header\n"))
    return PointCloud(rec["xyz"].copy(), rec["rgb"].copy())


def stripe_colours(stripe: np.ndarray, period: int = 0) -> np.ndarray:
    """Pseudo-colour per identified stripe (like the paper's Fig. 8b): neighbours clearly differ.

    Hue steps by the golden angle per stripe, so adjacent stripes never look alike; no value = black.
    """
    s = stripe.astype(np.int64)
    valid = s >= 0
    hue = ((s * 0.618033988749895) % 1.0 * 180).astype(np.uint8)
    hsv = np.stack([hue, np.full_like(hue, 255), np.full_like(hue, 230)], axis=-1)
    rgb = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    rgb[~valid] = 0
    return rgb


def depth_preview(depth: np.ndarray, depth_range_mm: tuple[float, float] | None = None) -> np.ndarray:
    """Colourised depth (TURBO, near = red), black where no value; RGB uint8."""
    m = depth > 0
    if depth_range_mm is None:
        lo, hi = (float(depth[m].min()), float(depth[m].max())) if m.any() else (0.0, 1.0)
    else:
        lo, hi = depth_range_mm
    t = np.clip((depth - lo) / max(hi - lo, 1e-6), 0, 1)
    g = ((1 - t) * 255).astype(np.uint8)
    bgr = cv2.applyColorMap(g, cv2.COLORMAP_TURBO)
    rgb = bgr[..., ::-1].copy()
    rgb[~m] = 0
    return rgb


def write_depth_png16(path: str | os.PathLike, depth: np.ndarray, scale: float = 10.0) -> None:
    """16-bit PNG depth in units of 1/scale mm (default 0.1 mm), 0 = no value."""
    d = np.clip(np.rint(depth * scale), 0, 65535).astype(np.uint16)
    write_rgb(path, d)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    write_rgb(path, image)
