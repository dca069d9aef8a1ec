"""A dense point sample of a true surface (the virtual rig's ground truth for whole models).

Binary little-endian PLY, vertices only: float32 x y z (mm), float32 nx ny nz (outward unit normal),
uint8 red green blue (the surface's albedo); written by drivers/sim/truth.py in the object's frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import InputError

_FLOATS = ("x", "y", "z", "nx", "ny", "nz")
_BYTES = ("red", "green", "blue")
_DTYPE = np.dtype([*((k, "<f4") for k in _FLOATS), *((k, "u1") for k in _BYTES)])


@dataclass
class SurfaceSample:
    points: np.ndarray  # (N, 3) float mm
    normals: np.ndarray  # (N, 3) unit, outward
    colors: np.ndarray  # (N, 3) uint8


def write_surface_sample(path: str | os.PathLike, s: SurfaceSample) -> None:
    rec = np.empty(len(s.points), _DTYPE)
    for i, k in enumerate("xyz"):
        rec[k] = s.points[:, i]
        rec["n" + k] = s.normals[:, i]
    for i, k in enumerate(("red", "green", "blue")):
        rec[k] = s.colors[:, i]
    props = "".join(f"property float {k}\n" for k in ("x", "y", "z", "nx", "ny", "nz"))
    props += "".join(f"property uchar {k}\n" for k in ("red", "green", "blue"))
    header = f"ply\nformat binary_little_endian 1.0\nelement vertex {len(rec)}\n{props}end_header\n"
    Path(path).write_bytes(header.encode("ascii") + rec.tobytes())


def read_surface_sample(path: str | os.PathLike) -> SurfaceSample:
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise InputError(f"{p}: cannot read the surface sample ({exc.strerror})") from None
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise InputError(f"{p}: not a PLY surface sample")
    head = data[:end].decode("ascii", "replace").splitlines()
    count = next((int(x.split()[2]) for x in head if x.startswith("element vertex")), -1)
    body = data[end + len(b"end_header\n") :]
    if count < 0 or len(body) != count * _DTYPE.itemsize:
        raise InputError(f"{p}: a truncated or foreign PLY (expected {count} vertices of x y z nx ny nz rgb)")
    rec = np.frombuffer(body, _DTYPE)
    pts = np.stack([rec[k] for k in "xyz"], axis=1).astype(np.float64)
    nrm = np.stack([rec["n" + k] for k in "xyz"], axis=1).astype(np.float64)
    col = np.stack([rec[k] for k in ("red", "green", "blue")], axis=1)
    return SurfaceSample(pts, nrm, col)
