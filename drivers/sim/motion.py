"""Rigid motion of a scene's moving objects (those marked `moves: true`), frame by frame.

At frame k (the rig's k-th render, counting from 0) every moving object is turned about one axis
and shifted, as one rigid body:

    X_k = Rot(k * rotation_deg_per_frame about rotation_axis) (X_0 - p) + p + s(k) * motion_mm_per_frame

- `motion_mm_per_frame` [x, y, z] mm: the translation per frame, camera frame (x right, y down,
  z away from the camera).
- `motion_bounce_frames` N: 0 = the translation goes on for ever, s(k) = k; N > 0 = the objects
  go out for N frames and back for N (s = 0, 1, ..., N, N - 1, ..., 0, 1, ...), so a live session
  keeps them in view. The rotation does not bounce.
- `rotation_deg_per_frame`: the angle per frame (degrees, right-handed about `rotation_axis`).
- `rotation_axis` [x, y, z]: its direction, camera frame; the default [0, -1, 0] is "up" (camera y
  points down), so a positive rate turns a turntable anticlockwise seen from above.
- `rotation_center_mm` [x, y, z]: a point p on the axis, camera mm, at frame 0; by default the
  mean of the moving objects' centres (an object's own centre when only one moves). The axis
  moves with the translation.

Without rotation a moving object's pose is its frame-0 pose shifted by s(k) * motion_mm_per_frame,
as the rig has always done (`Shape.translated`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.sim.shapes import Shape

MOTION_KEYS = (
    "motion_mm_per_frame",
    "motion_bounce_frames",
    "rotation_deg_per_frame",
    "rotation_axis",
    "rotation_center_mm",
)


def rotation_matrix(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """Right-handed rotation by angle_deg about a unit axis (Rodrigues' formula)."""
    k = np.asarray(axis, np.float64)
    a = np.deg2rad(angle_deg)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)


@dataclass(frozen=True)
class Motion:
    velocity: np.ndarray  # (3,) mm per frame
    bounce: int  # frames out before coming back; 0 = never
    rate_deg: float  # degrees per frame
    axis: np.ndarray  # (3,) unit
    centre: np.ndarray  # (3,) a point on the axis at frame 0, camera mm

    @classmethod
    def from_options(cls, options: object, shapes: list[Shape]) -> Motion:
        """From RigOptions (already checked) and the scene's shapes at frame 0."""
        v = np.asarray(options.motion_mm_per_frame, np.float64)
        axis = np.asarray(options.rotation_axis, np.float64)
        axis = axis / np.linalg.norm(axis)
        if options.rotation_center_mm is not None:
            centre = np.asarray(options.rotation_center_mm, np.float64)
        else:
            moving = [s.c for s in shapes if s.moves]
            centre = np.mean(moving, axis=0) if moving else np.zeros(3)
        return cls(v, int(options.motion_bounce_frames), float(options.rotation_deg_per_frame), axis, centre)

    @property
    def active(self) -> bool:
        return bool(np.any(self.velocity)) or self.rate_deg != 0.0

    def travel(self, step: int) -> int:
        """s(k): how many frames' worth of translation the objects are out at frame k."""
        n = self.bounce
        if n <= 0:
            return step
        m = step % (2 * n)
        return m if m <= n else 2 * n - m

    def shapes_at(self, base: list[Shape], step: int) -> list[Shape]:
        """The scene's shapes at frame `step`: moving ones re-posed, the others as they are."""
        if step == 0 or not self.active:
            return base
        shift = self.velocity * self.travel(step)
        if self.rate_deg == 0.0:
            return [s.translated(shift) if s.moves else s for s in base]
        Rm = rotation_matrix(self.axis, self.rate_deg * step)
        p = self.centre
        return [s.posed(Rm @ s.R, Rm @ (s.c - p) + p + shift) if s.moves else s for s in base]
