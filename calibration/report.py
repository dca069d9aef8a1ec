"""Human-readable figures of a calibration solve (CLI, wizard and bench share them)."""

from __future__ import annotations

import numpy as np

from calibration.response import Response
from calibration.solve import RECOMMENDED_POSES, Solution
from core.calibration import Calibration


def views_table(solution: Solution) -> str:
    lines = [f"{'pose':<10} {'used':<4} {'corners':>7} {'cam px':>7} {'proj px':>8} {'tilt':>6}  note"]
    for v in solution.views:
        tilt = f"{v.tilt_deg:5.1f}°" if np.isfinite(v.tilt_deg) else "    - "
        cam = f"{v.camera_rms:7.3f}" if np.isfinite(v.camera_rms) else "      -"
        prj = f"{v.projector_rms:8.3f}" if np.isfinite(v.projector_rms) else "       -"
        lines.append(f"{v.name:<10} {'yes' if v.used else 'no':<4} {v.corners:>7} {cam} {prj} {tilt}  {v.reason}")
    return "\n".join(lines)


def figures(cal: Calibration) -> str:
    K, Kp = cal.camera_matrix, cal.projector_matrix
    r = cal.rms
    return "\n".join(
        [
            f"camera RMS     {r.get('camera_rms', float('nan')):.3f} px   "
            f"projector RMS {r.get('projector_rms', float('nan')):.3f} px   "
            f"stereo RMS {r.get('stereo_rms', float('nan')):.3f} px",
            f"camera    {cal.camera_size[0]}x{cal.camera_size[1]}  f = {K[0, 0]:.2f}, {K[1, 1]:.2f}  "
            f"c = {K[0, 2]:.2f}, {K[1, 2]:.2f}  dist = {np.array2string(cal.camera_distortion, precision=4)}",
            f"projector {cal.projector_size[0]}x{cal.projector_size[1]}  f = {Kp[0, 0]:.2f}, {Kp[1, 1]:.2f}  "
            f"c = {Kp[0, 2]:.2f}, {Kp[1, 2]:.2f}  dist = {np.array2string(cal.projector_distortion, precision=4)}",
            f"baseline |T| = {cal.baseline_mm:.2f} mm  T = {np.array2string(cal.T, precision=2)}",
        ]
    )


def truth_errors(err: dict[str, float]) -> str:
    return (
        f"vs the rig's true calibration: focal {err['camera_focal_error_pct']:.3f} % (camera), "
        f"{err['projector_focal_error_pct']:.3f} % (projector); "
        f"principal point {err['camera_principal_error_px']:.2f} px, "
        f"{err['projector_principal_error_px']:.2f} px; |T| {err['baseline_error_mm']:.3f} mm; "
        f"rotation {err['rotation_error_deg']:.4f} deg"
    )


def response_text(resp: Response) -> str:
    m = np.array2string(resp.color_mixing, precision=3, suppress_small=True).replace("\n", "\n" + " " * 15)
    lines = [
        f"colour response: gamma R {resp.gamma[0]:.3f}  G {resp.gamma[1]:.3f}  B {resp.gamma[2]:.3f} "
        f"(projector level -> linear camera)",
        f"color_mixing = {m}",
    ]
    lines += [f"warning: {w}" for w in resp.warnings]
    return "\n".join(lines)


def verdict(solution: Solution) -> str:
    used = len(solution.used)
    if not solution.passed:
        return "verdict: NOT GOOD: " + "; ".join(solution.problems)
    retake = [v.name for v in solution.views if not v.used]
    more = f"; {RECOMMENDED_POSES - used} more poses recommended" if used < RECOMMENDED_POSES else ""
    again = f"; retake {', '.join(retake)}" if retake else ""
    return f"verdict: good ({used} poses used{more}{again})"
