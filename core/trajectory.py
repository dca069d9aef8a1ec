"""Trajectory files: one rigid pose per scan (estimated by `slscan fuse`, or the virtual rig's true ones).

CSV, one header line, then one line per scan:

    scan,frame_id,status,m00,m01,m02,m03,m10,m11,m12,m13,m20,m21,m22,m23

m is the 3x4 top of the 4x4 pose M (mm) mapping the scan's camera coordinates into the model's frame,
X_model = M X_camera; status is "ok" (registered and integrated), "dropped" (registration failed its test:
not integrated, M is the prediction it was tried from), or "true" (ground truth). The model's frame is
the camera's at the first scan.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import InputError

HEADER = "scan,frame_id,status," + ",".join(f"m{r}{c}" for r in range(3) for c in range(4))
STATUSES = ("ok", "dropped", "true")


@dataclass
class PoseRow:
    scan: int
    frame_id: int
    status: str
    pose: np.ndarray  # (4, 4)


def write_trajectory(path: str | os.PathLike, rows: list[PoseRow]) -> None:
    lines = [HEADER]
    for r in rows:
        m = np.asarray(r.pose, np.float64)[:3, :4].ravel()
        lines.append(f"{r.scan},{r.frame_id},{r.status}," + ",".join(f"{v:.9g}" for v in m))
    Path(path).write_text("\n".join(lines) + "\n")


def read_trajectory(path: str | os.PathLike) -> list[PoseRow]:
    p = Path(path)
    try:
        lines = p.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: cannot read the trajectory ({exc})") from None
    if not lines or lines[0].strip() != HEADER:
        raise InputError(f"{p}: not a trajectory file (expected the header {HEADER!r})")
    rows = []
    for n, line in enumerate(lines[1:], start=2):
        parts = line.strip().split(",")
        if len(parts) != 15 or parts[2] not in STATUSES:
            raise InputError(f"{p}:{n}: expected scan,frame_id,status and 12 numbers")
        try:
            m = np.array([float(v) for v in parts[3:]]).reshape(3, 4)
            scan, frame_id = int(parts[0]), int(parts[1])
        except ValueError:
            raise InputError(f"{p}:{n}: expected scan,frame_id,status and 12 numbers") from None
        pose = np.eye(4)
        pose[:3] = m
        rows.append(PoseRow(scan, frame_id, parts[2], pose))
    return rows
