"""The camera–projector solve: camera intrinsics, projector intrinsics, stereo extrinsics.

Input: per pose, the board corners' 3D board coordinates, their camera pixels and their projector
pixels (from local homographies). Camera and projector are each calibrated as pinhole cameras
(cv2.calibrateCamera), views whose reprojection error stands out are rejected with a reason, then
cv2.stereoCalibrate refines everything together with the camera first, so X_proj = R X_cam + T.
Pure: arrays in, a Calibration and a report out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from core.calibration import Calibration

MIN_POSES = 5  # fewer cannot constrain two intrinsic sets and the extrinsics with any margin
RECOMMENDED_POSES = 12
MIN_CORNERS = 12  # per pose, with both camera and projector coordinates
# Checks a solve must pass before its file is written (px): well above a healthy rig's figures.
MAX_CAMERA_RMS = 0.5
MAX_PROJECTOR_RMS = 1.0
MAX_STEREO_RMS = 1.0
# A view is an outlier when its error is this many times the median (and above the floor).
OUTLIER_FACTOR = 3.0
OUTLIER_FLOOR_PX = {"camera": 0.3, "projector": 0.6}
MIN_TILT_DEG = 10.0  # a pose counts as tilted above this angle between board normal and optical axis
# cv2 distortion model: k1 k2 p1 p2 (k3 fixed to 0: it overfits with a dozen poses)
FLAGS = cv2.CALIB_FIX_K3
CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)


@dataclass
class PoseObservation:
    name: str
    object_points: np.ndarray  # (N, 3) float32, mm on the board
    camera_points: np.ndarray  # (N, 2) float32
    projector_points: np.ndarray  # (N, 2) float32


@dataclass
class ViewReport:
    name: str
    used: bool
    reason: str = ""  # why it was rejected
    corners: int = 0
    camera_rms: float = float("nan")
    projector_rms: float = float("nan")
    tilt_deg: float = float("nan")
    tilt_axis_deg: float = float("nan")  # direction of the tilt in the image (0 = about the vertical axis)


@dataclass
class Solution:
    calibration: Calibration | None
    views: list[ViewReport]
    problems: list[str] = field(default_factory=list)  # failed checks; empty = good

    @property
    def passed(self) -> bool:
        return self.calibration is not None and not self.problems

    @property
    def used(self) -> list[ViewReport]:
        return [v for v in self.views if v.used]


def _per_view_rms(obj, img, rvecs, tvecs, K, D) -> list[float]:
    out = []
    for o, p, r, t in zip(obj, img, rvecs, tvecs, strict=True):
        q, _ = cv2.projectPoints(o, r, t, K, D)
        out.append(float(np.sqrt(((q.reshape(-1, 2) - p.reshape(-1, 2)) ** 2).sum(axis=1).mean())))
    return out


def _tilt(rvec: np.ndarray) -> tuple[float, float]:
    """Angle between the board normal and the camera axis, and the direction of that tilt."""
    Rm, _ = cv2.Rodrigues(rvec)
    n = Rm[:, 2]
    tilt = float(np.degrees(np.arccos(min(1.0, abs(n[2])))))
    s = 1.0 if n[2] >= 0 else -1.0
    axis = float(np.degrees(np.arctan2(s * n[1], s * n[0])) % 180.0)
    return tilt, axis


def tilt_problem(tilts: list[tuple[float, float]]) -> str | None:
    """Why the poses cannot constrain the focal lengths, or None: two tilt directions are needed."""
    tilted = [(t, a) for t, a in tilts if t >= MIN_TILT_DEG]
    if len(tilted) < 2:
        return (
            f"degenerate poses: only {len(tilted)} pose(s) tilted by {MIN_TILT_DEG:.0f} deg or more "
            f"(all nearly fronto-parallel); tilt the board left/right and up/down by 20-40 deg"
        )
    axes = np.array([a for _, a in tilted])
    spread = max(min(abs(a - b), 180 - abs(a - b)) for a in axes for b in axes)
    if spread < 30:
        return (
            f"degenerate poses: every tilted pose leans the same way (within {spread:.0f} deg); "
            f"also tilt the board about the other axis"
        )
    return None


def _calibrate(obj, img, size, K0=None):
    flags = FLAGS | (cv2.CALIB_USE_INTRINSIC_GUESS if K0 is not None else 0)
    D0 = np.zeros(5) if K0 is not None else None
    rms, K, D, rvecs, tvecs = cv2.calibrateCamera(obj, img, size, K0, D0, flags=flags, criteria=CRITERIA)
    return rms, K, D.ravel(), rvecs, tvecs


def solve(
    poses: list[PoseObservation],
    camera_size: tuple[int, int],
    projector_size: tuple[int, int],
    rejected: list[ViewReport] | None = None,
) -> Solution:
    """Calibrate; `rejected` are poses already refused upstream (no board, undecodable Gray code)."""
    views = list(rejected or [])
    active: list[int] = []
    reports: dict[int, ViewReport] = {}
    for i, p in enumerate(poses):
        rep = ViewReport(p.name, True, corners=len(p.object_points))
        reports[i] = rep
        if len(p.object_points) < MIN_CORNERS:
            rep.used = False
            rep.reason = (
                f"only {len(p.object_points)} corners with camera and projector coordinates (need {MIN_CORNERS})"
            )
        else:
            active.append(i)

    def finish(problem: str) -> Solution:
        return Solution(None, views + [reports[i] for i in range(len(poses))], [problem])

    if len(active) < MIN_POSES:
        return finish(f"too few usable poses: {len(active)} (minimum {MIN_POSES}, recommended {RECOMMENDED_POSES})")

    def arrays(idx):
        obj = [poses[i].object_points.astype(np.float32).reshape(-1, 1, 3) for i in idx]
        cam = [poses[i].camera_points.astype(np.float32).reshape(-1, 1, 2) for i in idx]
        prj = [poses[i].projector_points.astype(np.float32).reshape(-1, 1, 2) for i in idx]
        return obj, cam, prj

    # Calibrate each device; drop views that stand out, a few at a time, then calibrate again.
    for _ in range(4):
        obj, cam, prj = arrays(active)
        try:
            _, K1, D1, rv1, tv1 = _calibrate(obj, cam, camera_size)
            _, K2, D2, rv2, tv2 = _calibrate(obj, prj, projector_size)
        except cv2.error as exc:
            return finish(f"the solve failed ({str(exc).strip().splitlines()[-1]}); add poses with more tilt variety")
        e1 = _per_view_rms(obj, cam, rv1, tv1, K1, D1)
        e2 = _per_view_rms(obj, prj, rv2, tv2, K2, D2)
        for i, a, b, r in zip(active, e1, e2, rv1, strict=True):
            reports[i].camera_rms, reports[i].projector_rms = a, b
            reports[i].tilt_deg, reports[i].tilt_axis_deg = _tilt(r)
        bad: list[int] = []
        for kind, errs in (("camera", e1), ("projector", e2)):
            med = float(np.median(errs))
            limit = max(OUTLIER_FACTOR * med, OUTLIER_FLOOR_PX[kind])
            for i, e in zip(active, errs, strict=True):
                if e > limit and i not in bad:
                    bad.append(i)
                    reports[i].used = False
                    reports[i].reason = (
                        f"{kind} reprojection error {e:.2f} px is more than {OUTLIER_FACTOR:.0f}x the median "
                        f"({med:.2f} px): board moved during capture, blurred, or a wrong detection"
                    )
        if not bad:
            break
        active = [i for i in active if i not in bad]
        if len(active) < MIN_POSES:
            return finish(f"too few usable poses after rejecting outliers: {len(active)} (minimum {MIN_POSES})")

    problem = tilt_problem([(reports[i].tilt_deg, reports[i].tilt_axis_deg) for i in active])
    if problem:
        return finish(problem)

    obj, cam, prj = arrays(active)
    flags = FLAGS | cv2.CALIB_USE_INTRINSIC_GUESS
    try:
        out = cv2.stereoCalibrateExtended(
            obj, cam, prj, K1, D1, K2, D2, camera_size, np.eye(3), np.zeros((3, 1)), flags=flags, criteria=CRITERIA
        )
    except cv2.error as exc:
        return finish(f"the stereo solve failed ({str(exc).strip().splitlines()[-1]})")
    stereo_rms, K1, D1, K2, D2, R, T = out[:7]
    rvecs, tvecs = out[9], out[10]
    e1 = _per_view_rms(obj, cam, rvecs, tvecs, K1, D1)
    e2 = []
    for o, p, r, t in zip(obj, prj, rvecs, tvecs, strict=True):
        Rv, _ = cv2.Rodrigues(r)
        r2, _ = cv2.Rodrigues(R @ Rv)
        q, _ = cv2.projectPoints(o, r2, R @ t.reshape(3, 1) + T.reshape(3, 1), K2, D2)
        e2.append(float(np.sqrt(((q.reshape(-1, 2) - p.reshape(-1, 2)) ** 2).sum(axis=1).mean())))
    for i, a, b in zip(active, e1, e2, strict=True):
        reports[i].camera_rms, reports[i].projector_rms = a, b
    n_pts = np.array([len(o) for o in obj], float)
    camera_rms = float(np.sqrt((np.array(e1) ** 2 * n_pts).sum() / n_pts.sum()))
    projector_rms = float(np.sqrt((np.array(e2) ** 2 * n_pts).sum() / n_pts.sum()))
    cal = Calibration(
        camera_size=camera_size,
        camera_matrix=K1,
        camera_distortion=D1,
        projector_size=projector_size,
        projector_matrix=K2,
        projector_distortion=D2,
        R=R,
        T=T,
        rms={"camera_rms": camera_rms, "projector_rms": projector_rms, "stereo_rms": float(stereo_rms)},
    )
    problems = []
    if camera_rms > MAX_CAMERA_RMS:
        problems.append(f"camera RMS {camera_rms:.3f} px is above {MAX_CAMERA_RMS} px")
    if projector_rms > MAX_PROJECTOR_RMS:
        problems.append(f"projector RMS {projector_rms:.3f} px is above {MAX_PROJECTOR_RMS} px")
    if stereo_rms > MAX_STEREO_RMS:
        problems.append(f"stereo RMS {stereo_rms:.3f} px is above {MAX_STEREO_RMS} px")
    try:
        cal.check("solve")
    except Exception as exc:  # an impossible result is a failed check, not a crash
        problems.append(str(exc))
    return Solution(cal, views + [reports[i] for i in range(len(poses))], problems)
