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


# PLY property types slscan reads (the binary little-endian ones other tools write for points)
_PLY_TYPES = {
    "float": "<f4",
    "float32": "<f4",
    "double": "<f8",
    "float64": "<f8",
    "uchar": "u1",
    "uint8": "u1",
    "char": "i1",
    "int8": "i1",
    "ushort": "<u2",
    "uint16": "<u2",
    "short": "<i2",
    "int16": "<i2",
    "uint": "<u4",
    "uint32": "<u4",
    "int": "<i4",
    "int32": "<i4",
}


def write_ply(path: str | os.PathLike, cloud: PointCloud) -> None:
    """Binary little-endian PLY: x y z float32, with the cloud's normals nx ny nz float32, then red green blue
    uchar (the vertex layout Open3D and MeshLab write)."""
    n = len(cloud.xyz)
    normals = cloud.normals is not None
    props = "property float x\nproperty float y\nproperty float z\n"
    fields: list = [("xyz", "<f4", 3)]
    if normals:
        props += "property float nx\nproperty float ny\nproperty float nz\n"
        fields.append(("normal", "<f4", 3))
    fields.append(("rgb", "u1", 3))
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment slscan point cloud, camera frame, mm\n"
        + ("comment normals: unit, facing the camera, 0 0 0 = none\n" if normals else "")
        + f"element vertex {n}\n{props}"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    rec = np.empty(n, dtype=fields)
    rec["xyz"] = cloud.xyz
    if normals:
        rec["normal"] = cloud.normals
    rec["rgb"] = cloud.rgb
    try:
        with open(path, "wb") as f:
            f.write(header.encode("ascii"))
            f.write(rec.tobytes())
    except OSError as exc:
        raise InputError(f"{path}: cannot write PLY ({exc.strerror})") from None


def read_ply(path: str | os.PathLike) -> PointCloud:
    """Read a binary little-endian PLY point cloud whose first element is the vertices: x y z, and where present
    nx ny nz and red green blue (what `write_ply` writes, with or without normals)."""
    path = Path(path)
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise InputError(f"{path}: not a PLY file")
    header = data[:end].decode("ascii", errors="replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise InputError(f"{path}: only binary little-endian PLY is read")
    n: int | None = None
    fields: list[tuple[str, str]] = []
    for line in header:
        words = line.split()
        if words[:2] == ["element", "vertex"] and len(words) == 3 and words[2].isdigit():
            n = int(words[2])
        elif words[:1] == ["element"] and n is not None:
            break  # (later elements, faces: not read)
        elif words[:1] == ["property"] and n is not None:
            if len(words) != 3 or words[1] not in _PLY_TYPES:
                raise InputError(f"{path}: vertex property {' '.join(words[1:])!r} is not read (only scalar numbers)")
            fields.append((words[2], _PLY_TYPES[words[1]]))
    if n is None:
        raise InputError(f"{path}: no vertex element")
    names = [f for f, _ in fields]
    if not {"x", "y", "z"} <= set(names) or len(set(names)) != len(names):
        raise InputError(f"{path}: the vertex element needs properties x, y, z, each once")
    dtype = np.dtype(fields)
    offset = end + len("end_header\n")
    if len(data) - offset < n * dtype.itemsize:
        raise InputError(
            f"{path}: {n} vertices announced but the file ends after {(len(data) - offset) // dtype.itemsize}"
        )
    rec = np.frombuffer(data, dtype=dtype, count=n, offset=offset)
    xyz = np.stack([rec[c] for c in "xyz"], axis=1).astype(np.float32)
    rgb = (
        np.stack([rec[c] for c in ("red", "green", "blue")], axis=1).astype(np.uint8)
        if {"red", "green", "blue"} <= set(names)
        else np.full((n, 3), 255, np.uint8)
    )
    normals = (
        np.stack([rec[c] for c in ("nx", "ny", "nz")], axis=1).astype(np.float32)
        if {"nx", "ny", "nz"} <= set(names)
        else None
    )
    return PointCloud(xyz, rgb, normals)


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


# Units per metre of the 16-bit depth PNG (Open3D's `depth_scale`): 0.1 mm steps, depths up to 6.5535 m.
DEPTH_PNG_SCALE = 10000.0


def write_depth_png16(path: str | os.PathLike, depth: np.ndarray, depth_scale: float = DEPTH_PNG_SCALE) -> None:
    """16-bit one-channel PNG of depth in mm: value = depth in metres x depth_scale (units per metre, as Open3D's
    RGBD reader takes it: 1000 = mm, the default 10000 = 0.1 mm); 0 = no value, and so is a depth beyond 65535 units
    (a clipped value would be a wrong depth)."""
    if not (np.isfinite(depth_scale) and depth_scale > 0):
        raise InputError(f"depth scale {depth_scale}: must be a positive number of units per metre")
    units = np.rint(depth.astype(np.float64) * (depth_scale / 1000.0))
    units[~(units <= 65535)] = 0  # (also NaN)
    write_rgb(path, np.clip(units, 0, 65535).astype(np.uint16))


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    write_rgb(path, image)
