"""The calibration wizard's bookkeeping, free of any window: poses, coverage, tilt variety, hints.

The operator window (calibration/wizard.py) only draws what this holds and forwards keys.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from calibration.board import Board, Detection
from calibration.capture import CaptureWriter, PoseFrames
from calibration.session import Decoder, PoseResult, observe_pose
from calibration.solve import MIN_POSES, MIN_TILT_DEG, RECOMMENDED_POSES, Solution, solve

GRID = (8, 6)  # coverage cells across / down each field
TILT_BINS = ("left", "right", "up", "down")
TILT_HINT_DEG = 15.0  # a direction counts as covered from this tilt on


def overlay(image: np.ndarray, det: Detection | None) -> np.ndarray:
    """The camera image with the detected corners drawn (green) or a red frame when none."""
    out = np.ascontiguousarray(image if image.dtype == np.uint8 else (image >> 8).astype(np.uint8)).copy()
    if det is None:
        cv2.rectangle(out, (2, 2), (out.shape[1] - 3, out.shape[0] - 3), (255, 0, 0), 3)
        return out
    for x, y in det.corners:
        cv2.circle(out, (round(float(x)), round(float(y))), 3, (0, 255, 0), 1, cv2.LINE_AA)
    return out


def cells(points: np.ndarray, size: tuple[int, int], grid: tuple[int, int] = GRID) -> np.ndarray:
    """Coverage cells (rows, cols) bool touched by the convex hull of `points` in a w x h field."""
    w, h = size
    mask = np.zeros((grid[1], grid[0]), bool)
    if len(points) < 3:
        return mask
    hull = cv2.convexHull(points.astype(np.float32).reshape(-1, 1, 2))
    scaled = (hull.reshape(-1, 2) * [grid[0] / w, grid[1] / h] * 16).astype(np.int32)
    img = np.zeros((grid[1] * 16, grid[0] * 16), np.uint8)
    cv2.fillConvexPoly(img, scaled, 1)
    return img.reshape(grid[1], 16, grid[0], 16).mean(axis=(1, 3)) > 0.5


def tilt_direction(rvec: np.ndarray) -> tuple[float, list[str]]:
    """Tilt angle (deg) of a board pose and the directions it covers (left/right/up/down)."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    n = R[:, 2] * (-1 if R[2, 2] > 0 else 1)  # normal pointing at the camera
    tilt = float(np.degrees(np.arccos(min(1.0, abs(n[2])))))
    s = np.sin(np.deg2rad(TILT_HINT_DEG))
    dirs = []
    if n[0] > s:
        dirs.append("right")
    if n[0] < -s:
        dirs.append("left")
    if n[1] > s:
        dirs.append("down")
    if n[1] < -s:
        dirs.append("up")
    return tilt, dirs


@dataclass
class WizardState:
    board: Board
    camera_size: tuple[int, int]
    projector_size: tuple[int, int]
    writer: CaptureWriter | None = None
    guess_focal_px: float | None = None  # for tilt estimates before the first solve
    poses: list[PoseResult] = field(default_factory=list)
    tilts: list[tuple[float, list[str]]] = field(default_factory=list)
    solution: Solution | None = None
    messages: list[str] = field(default_factory=list)

    # -- capture ------------------------------------------------------------------------------
    def add_pose(
        self,
        frames: list[np.ndarray],
        patterns_meta: dict,
        decode: Decoder,
        timestamps_ns: list[int] | None = None,
        frame_ids: list[int] | None = None,
        note: str = "",
    ) -> PoseResult:
        """Observe a captured pose at once; keep it only if it gives corners (say why if not).

        note: what the capture had to retake (said with the pose's figures).
        """
        name = f"pose_{len(self.poses):03d}"
        result = observe_pose(self.board, PoseFrames(name, frames, patterns_meta), decode)
        if result.observation is None:
            self.say(f"not kept: {result.rejected.reason}")
            return result
        if self.writer is not None:
            self.writer.add_pose(frames, timestamps_ns=timestamps_ns, frame_ids=frame_ids)
        self.poses.append(result)
        self.tilts.append(self._tilt(result))
        self.resolve()
        err = self.pose_error(len(self.poses) - 1)
        fig = f"camera {err[0]:.3f} px, projector {err[1]:.3f} px" if err else f"error after {MIN_POSES} poses"
        self.say(f"{name}: {len(result.observation.object_points)} corners, tilt {self.tilts[-1][0]:.0f}°; {fig}")
        if note:
            self.say(f"{name}: {note}")
        return result

    def undo(self) -> None:
        if not self.poses:
            self.say("nothing to undo")
            return
        gone = self.poses.pop()
        self.tilts.pop()
        if self.writer is not None:
            self.writer.remove_last_pose()
        self.resolve()
        self.say(f"{gone.name} removed")

    def resolve(self) -> None:
        obs = [p.observation for p in self.poses if p.observation is not None]
        self.solution = solve(obs, self.camera_size, self.projector_size) if len(obs) >= MIN_POSES else None

    def _tilt(self, result: PoseResult) -> tuple[float, list[str]]:
        obs = result.observation
        if self.solution is not None and self.solution.calibration is not None:
            K = self.solution.calibration.camera_matrix
            D = self.solution.calibration.camera_distortion
        else:
            w, h = self.camera_size
            f = self.guess_focal_px or 1.5 * max(w, h)
            K, D = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]), np.zeros(5)
        ok, rvec, _ = cv2.solvePnP(obs.object_points, obs.camera_points, K, D)
        return tilt_direction(rvec) if ok else (0.0, [])

    def say(self, text: str) -> None:
        self.messages.append(text)
        del self.messages[:-6]

    # -- what the window shows ------------------------------------------------------------------
    def pose_error(self, i: int) -> tuple[float, float] | None:
        if self.solution is None:
            return None
        for v in self.solution.views:
            if v.name == self.poses[i].name:
                return (v.camera_rms, v.projector_rms) if v.used else None
        return None

    def camera_coverage(self) -> np.ndarray:
        out = np.zeros((GRID[1], GRID[0]), bool)
        for p in self.poses:
            out |= cells(p.observation.camera_points, self.camera_size)
        return out

    def projector_coverage(self) -> np.ndarray:
        out = np.zeros((GRID[1], GRID[0]), bool)
        for p in self.poses:
            out |= cells(p.observation.projector_points, self.projector_size)
        return out

    def missing_tilts(self) -> list[str]:
        have = {d for _, dirs in self.tilts for d in dirs}
        return [d for d in TILT_BINS if d not in have]

    def hints(self) -> list[str]:
        n = len(self.poses)
        out = [f"poses {n} (minimum {MIN_POSES}, recommended {RECOMMENDED_POSES})"]
        missing = self.missing_tilts()
        if missing:
            out.append(
                f"tilt the board {', '.join(missing)} by 20-40° (poses tilted < {MIN_TILT_DEG:.0f}° teach little)"
            )
        cam = self.camera_coverage().mean() * 100
        prj = self.projector_coverage().mean() * 100
        out.append(f"coverage: camera field {cam:.0f} %, projector field {prj:.0f} %")
        if n and cam < 60:
            out.append("move the board towards the uncovered corners of the camera view")
        if self.solution is not None:
            bad = [v.name for v in self.solution.views if not v.used]
            if bad:
                out.append(f"retake (undo) {', '.join(bad)}")
        return out

    def ready(self) -> bool:
        return self.solution is not None and self.solution.passed and not self.missing_tilts()
