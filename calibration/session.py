"""From captured poses to a calibration: detect, decode, map corners, solve, measure colour.

Used alike by `slscan calibrate --from`, `--auto` and the wizard (which calls `observe_pose` on
each pose as soon as it is captured, for the per-pose figures).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from calibration.board import Board, detect
from calibration.capture import Capture, PoseFrames
from calibration.correspondence import decode_projector_maps
from calibration.local_homography import corners_to_projector
from calibration.response import Response, measure_response
from calibration.solve import MIN_POSES, RECOMMENDED_POSES, PoseObservation, Solution, ViewReport, solve
from core.calibration import Calibration
from core.errors import InputError

MIN_DECODED_FRACTION = 0.5  # of the detected corners that must get projector coordinates

Decoder = Callable[[list[np.ndarray], dict], tuple[np.ndarray, np.ndarray]]


@dataclass
class PoseResult:
    name: str
    observation: PoseObservation | None
    rejected: ViewReport | None  # why the pose gives nothing
    corners_camera: np.ndarray | None = None  # all detected corners (for coverage displays)
    corners_projector: np.ndarray | None = None  # those with projector coordinates


def observe_pose(board: Board, pose: PoseFrames, decode: Decoder = decode_projector_maps) -> PoseResult:
    """Board corners in the camera (white frame) and in the projector (local homographies)."""
    det = detect(board, pose.white)
    if det is None:
        why = "no board found in the white frame (is the whole board in view, in focus, lit?)"
        return PoseResult(pose.name, None, ViewReport(pose.name, False, why))
    column, row = decode(pose.frames, pose.patterns_meta)
    valid = np.isfinite(column) & np.isfinite(row)
    proj, ok = corners_to_projector(det.corners, column, row, valid)
    if ok.sum() < MIN_DECODED_FRACTION * len(det):
        why = (
            f"Gray code undecodable on the board: only {int(ok.sum())} of {len(det)} corners got projector "
            f"coordinates (is the projector lighting the whole board? too dark or saturated?)"
        )
        return PoseResult(pose.name, None, ViewReport(pose.name, False, why, corners=len(det)), det.corners)
    obj = board.object_points()[det.ids]
    obs = PoseObservation(pose.name, obj[ok], det.corners[ok], proj[ok].astype(np.float32))
    return PoseResult(pose.name, obs, None, det.corners, proj[ok])


@dataclass
class CaptureResult:
    solution: Solution
    response: Response | None
    true_calibration: Calibration | None
    pose_results: list[PoseResult] = field(default_factory=list)

    @property
    def calibration(self) -> Calibration | None:
        return self.solution.calibration


def solve_capture(
    capture: Capture,
    decode: Decoder = decode_projector_maps,
    camera_gamma: float | None = None,
    progress: Callable[[str], None] | None = None,
) -> CaptureResult:
    """Solve a capture folder pose by pose (frames are not all held at once)."""
    if len(capture.poses) < MIN_POSES:
        raise InputError(
            f"{capture.folder}: too few poses: {len(capture.poses)} (minimum {MIN_POSES}, "
            f"recommended {RECOMMENDED_POSES}); capture more"
        )
    results: list[PoseResult] = []
    camera_size = projector_size = None
    for name in capture.poses:
        pose = capture.read_pose(name)
        h, w = pose.frames[0].shape[:2]
        if camera_size is None:
            camera_size, projector_size = (w, h), pose.projector_size
        elif (w, h) != camera_size or pose.projector_size != projector_size:
            raise InputError(
                f"{capture.folder / name}: frames {w}x{h} / projector {pose.projector_size} differ from "
                f"the first pose ({camera_size}, {projector_size})"
            )
        r = observe_pose(capture.board, pose, decode)
        results.append(r)
        if progress:
            if r.rejected:
                progress(f"{name}: skipped: {r.rejected.reason}")
            else:
                progress(f"{name}: {len(r.observation.object_points)} corners")
    assert camera_size is not None and projector_size is not None
    obs = [r.observation for r in results if r.observation is not None]
    rejected = [r.rejected for r in results if r.rejected is not None]
    solution = solve(obs, camera_size, projector_size, rejected)
    solution.views.sort(key=lambda v: v.name)
    response = None
    if capture.has_response():
        if camera_gamma is None:
            camera_gamma = capture.response_camera_gamma() or 1.0
        try:
            response = measure_response(capture.read_response(), camera_gamma=camera_gamma)
        except ValueError as exc:
            solution.problems.append(f"colour response: {exc}")
    if solution.calibration is not None and response is not None:
        solution.calibration.color_mixing = response.color_mixing
        solution.calibration.extra.update(response.as_extra())
        solution.calibration.extra["camera_gamma"] = float(camera_gamma)  # the decoders read this key
    try:
        truth = capture.true_calibration()
    except Exception:  # a stored truth is optional; a broken one must not stop the solve
        truth = None
    return CaptureResult(solution, response, truth, results)
