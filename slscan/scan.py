"""A decoded scan: the depth map and, computed when first asked for, its points, colours and normals."""

from __future__ import annotations

from functools import cached_property

import numpy as np

from app.normals import grid_normals, grid_points


class Scan:
    """One decoded frame set.

    depth: H x W float32, Z in the camera frame in mm, 0 = none. valid: H x W bool, depth > 0. column: H x W
    float32 projector column of each pixel (NaN = none). image: the RGB frame that colours the points.
    points, colors, normals: one row per valid pixel, in row-major pixel order (the order of depth[valid]):
    N x 3 float32 mm (camera frame: x right, y down, z forward), N x 3 uint8 RGB, N x 3 float32 unit normals
    facing the camera (NaN where a pixel has no neighbour on its surface along a row or a column).
    frame_ids, timestamp_ns: the camera's ids of the set's frames (pattern order) and the newest frame's time, where
    known (live scans, dumps).
    """

    def __init__(
        self,
        depth: np.ndarray,
        column: np.ndarray,
        image: np.ndarray,
        ray: np.ndarray,
        frame_ids: tuple[int, ...] = (),
        timestamp_ns: int | None = None,
    ) -> None:
        self.depth = depth
        self.column = column
        self.image = image
        self.frame_ids = tuple(frame_ids)
        self.timestamp_ns = timestamp_ns
        self._ray = ray  # normalised camera ray (x/z, y/z) per pixel, from the calibration

    @cached_property
    def valid(self) -> np.ndarray:
        return self.depth > 0

    @cached_property
    def points(self) -> np.ndarray:
        return grid_points(self.depth, self._ray)[self.valid]

    @cached_property
    def colors(self) -> np.ndarray:
        img = self.image if self.image.dtype == np.uint8 else (self.image >> 8).astype(np.uint8)
        return np.ascontiguousarray(img[self.valid])

    @cached_property
    def normals(self) -> np.ndarray:
        return grid_normals(self.depth, self._ray)[self.valid]

    def __repr__(self) -> str:
        h, w = self.depth.shape
        return f"Scan({w}x{h}, {int(self.valid.sum())} points, frame_ids={self.frame_ids})"
