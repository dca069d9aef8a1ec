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

A hand-held path adds, after the above, a smooth random wander w(k) about the same centre p:

    X_k = Rot(w_rot(k)) (X'_k - p') + p' + w_shift(k),   p' = p + s(k) * motion_mm_per_frame

- `wander_mm` [x, y, z]: the translation's amplitude per camera axis (mm); `wander_deg` [x, y, z]: the
  rotation vector's amplitude per axis (degrees); both 0 = no wander.
- `wander_period_frames`: the typical period; each component is a sum of three sines whose periods lie
  within 2/3..2 of it, with seeded phases (`wander_seed`), so a component moves at most
  amplitude * 2 pi * 1.5 / period per frame. w(0) = 0: frame 0 is the scene as written.

`Motion.pose(k)` is the rigid map (R, t) of frame 0's moving objects to frame k's: X_k = R X_0 + t.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drivers.sim.shapes import Shape

MOTION_KEYS = (
    "motion_mm_per_frame",
    "motion_bounce_frames",
    "rotation_deg_per_frame",
    "rotation_axis",
    "rotation_center_mm",
    "wander_mm",
    "wander_deg",
    "wander_period_frames",
    "wander_seed",
)

_WANDER_TERMS = 3  # sines per component


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
    wander_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) amplitudes
    wander_deg: np.ndarray = field(default_factory=lambda: np.zeros(3))
    wander_period: float = 240.0  # frames
    wander_seed: int = 0

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
        return cls(
            v,
            int(options.motion_bounce_frames),
            float(options.rotation_deg_per_frame),
            axis,
            centre,
            np.asarray(options.wander_mm, np.float64),
            np.asarray(options.wander_deg, np.float64),
            float(options.wander_period_frames),
            int(options.wander_seed),
        )

    @property
    def wanders(self) -> bool:
        return bool(np.any(self.wander_mm) or np.any(self.wander_deg))

    @property
    def active(self) -> bool:
        return bool(np.any(self.velocity)) or self.rate_deg != 0.0 or self.wanders

    def _wander(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """(rotation vector in degrees, shift in mm) of the wander at frame `step`; both zero at frame 0."""
        rng = np.random.default_rng(self.wander_seed)
        # periods within 2/3..2 of the typical one, phases uniform; per component (6) and term (3)
        freq = rng.uniform(0.5, 1.5, (6, _WANDER_TERMS)) / self.wander_period
        phase = rng.uniform(0.0, 2.0 * np.pi, (6, _WANDER_TERMS))
        weight = rng.uniform(0.5, 1.0, (6, _WANDER_TERMS))
        weight /= weight.sum(axis=1, keepdims=True)
        arg = 2.0 * np.pi * freq * step + phase
        w = (weight * (np.sin(arg) - np.sin(phase))).sum(axis=1)
        return w[:3] * self.wander_deg, w[3:] * self.wander_mm

    def pose(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """(R, t): frame 0's moving objects to frame `step`'s, X_k = R X_0 + t (camera mm)."""
        shift = self.velocity * self.travel(step) if self.active else np.zeros(3)
        Rm = rotation_matrix(self.axis, self.rate_deg * step)
        p = self.centre
        R, t = Rm, p - Rm @ p + shift
        if self.wanders:
            rot_deg, move = self._wander(step)
            angle = float(np.linalg.norm(rot_deg))
            Rw = rotation_matrix(rot_deg / angle, angle) if angle > 0 else np.eye(3)
            q = p + shift
            R, t = Rw @ R, Rw @ (t - q) + q + move
        return R, t

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
        if self.wanders:
            R, t = self.pose(step)
            return [s.posed(R @ s.R, R @ s.c + t) if s.moves else s for s in base]
        shift = self.velocity * self.travel(step)
        if self.rate_deg == 0.0:
            return [s.translated(shift) if s.moves else s for s in base]
        Rm = rotation_matrix(self.axis, self.rate_deg * step)
        p = self.centre
        return [s.posed(Rm @ s.R, Rm @ (s.c - p) + p + shift) if s.moves else s for s in base]
