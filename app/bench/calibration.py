"""`slscan bench --calibration`: the calibration wizard's solve against the virtual rig's truth.

Poses the simulated board N times (effects on: noise, blur, crosstalk, gamma), solves as
`slscan calibrate --auto` does, and compares with the rig's true calibration; then scans the flat
`plane` scene with Gray code and triangulates it with the recovered calibration (and, for
reference, with the true one) against the ground-truth depth.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from app.argtypes import non_negative_int, positive_int

FLAG = "--calibration"
KEY = "calibration"
HELP = "calibration accuracy on the virtual rig: RMS, focal, principal point, baseline, rotation, plane depth"
DEFAULT = False  # a minute or two: run it when asked

TARGETS = {
    "camera_rms_px": 0.2,
    "projector_rms_px": 0.3,
    "camera_focal_error_pct": 0.5,
    "projector_focal_error_pct": 0.5,
    "camera_principal_error_px": 2.0,
    "projector_principal_error_px": 2.0,
    "baseline_error_mm": 0.5,
    "rotation_error_deg": 0.1,
    "plane_depth_error_pct": 0.2,
    "color_mixing_error": 0.03,
    "projector_gamma_error_pct": 3.0,
}
# the calibrated geometry's targets alone (what a capture of the poses is judged by, before plane checks)
GEOMETRY_TARGETS = {
    key: TARGETS[key]
    for key in (
        "camera_focal_error_pct",
        "projector_focal_error_pct",
        "camera_principal_error_px",
        "projector_principal_error_px",
        "baseline_error_mm",
        "rotation_error_deg",
    )
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--calibration-poses", type=positive_int, default=15, metavar="N", help="board poses (default 15)"
    )
    parser.add_argument("--calibration-scene", default="checkerboard", help="board scene (checkerboard, charuco)")
    parser.add_argument(
        "--calibration-seed", type=non_negative_int, default=0, metavar="S", help="pose seed (default 0)"
    )
    parser.add_argument(
        "--calibration-rig",
        type=non_negative_int,
        default=None,
        metavar="SEED",
        help="film the poses through the virtual rig's drivers opened from a rig file (device protocol, "
        "trigger, 30 Hz), as on real hardware, with sim seed SEED (checkerboard only)",
    )


def plane_depth(cal, truth, decode) -> dict[str, float]:
    """Gray-code scan of the flat `plane` scene, triangulated with `cal` and with the truth."""
    from calibration.auto import make_rig
    from calibration.validate import plane_scan
    from core.patterns import graycode_patterns

    rig = make_rig("plane")
    pats = graycode_patterns(rig.projector_size)
    frames = [rig.render(img) for img in pats.images]
    meta = {"size": list(pats.size), **pats.params}
    column, _ = decode(frames, meta)
    gt = rig.ground_truth
    got = plane_scan(column, cal, rig.depth_range_mm, gt.depth)
    ref = plane_scan(column, truth, rig.depth_range_mm, gt.depth)
    return {
        "plane_depth_error_pct": got.depth_error_pct,
        "plane_depth_abs_error_pct": got.depth_abs_error_pct,
        "plane_rms_mm": got.plane_rms_mm,
        "plane_depth_error_pct_true_cal": ref.depth_error_pct,
    }


RIG_YAML = """\
rig:
  camera: &sim {{driver: sim, scene: {scene}, seed: {seed}}}
  projector: *sim
  trigger: *sim
capture:
  rate_hz: 30
"""


def rig_capture(out: Path, n: int, scene: str, sim_seed: int, pose_seed: int):
    """Film n poses through the sim drivers of a rig file (RigBoardSource); -> (capture folder, rig).

    30 Hz: the simulated camera renders each frame when grabbed, and on a shared 2-core machine 60 Hz
    leaves the projector thread too little time to flip before every tick.
    """
    from app.config import load_config
    from calibration.auto import fronto_pose, rig_board
    from calibration.capture import CaptureWriter
    from calibration.poses import plan_poses
    from calibration.rig_source import RigBoardSource
    from drivers.sim.devices import forget_shared_benches, shared_bench

    out.mkdir(parents=True)
    path = out.parent / "rig.yaml"
    path.write_text(RIG_YAML.format(scene=scene, seed=sim_seed))
    bench = shared_bench(scene=scene, seed=sim_seed)  # what the registry's "sim" devices share
    rig = bench.rig
    src = RigBoardSource(load_config(path), rig_board(rig))
    try:
        writer = CaptureWriter(out / "capture", src.board, src.patterns)
        for rvec, tvec in plan_poses(src.board, rig.calibration, n, seed=pose_seed):
            rig.set_board_pose(rvec, tvec)
            take = src.capture()
            writer.add_pose(take.frames, timestamps_ns=take.timestamps_ns, frame_ids=take.frame_ids)
        rig.set_board_pose(*fronto_pose(src.board, rig))
        writer.write_response(src.levels(), camera_gamma=float(rig.options.camera_gamma))
    finally:
        src.close()
        forget_shared_benches()
    return out / "capture", rig


def run(args: argparse.Namespace) -> list[dict]:
    from calibration.auto import auto_capture, make_rig
    from calibration.capture import open_capture
    from calibration.correspondence import decode_projector_maps
    from calibration.session import solve_capture
    from calibration.validate import compare

    n = int(getattr(args, "calibration_poses", 15))
    scene = getattr(args, "calibration_scene", "checkerboard")
    pose_seed = int(getattr(args, "calibration_seed", 0))
    sim_seed = getattr(args, "calibration_rig", None)
    with tempfile.TemporaryDirectory(prefix="slscan-bench-cal-") as tmp:
        t0 = time.perf_counter()
        if sim_seed is None:
            rig = make_rig(scene)
            folder = auto_capture(Path(tmp) / "capture", n, rig=rig, seed=pose_seed)
        else:
            folder, rig = rig_capture(Path(tmp) / "rig", n, scene, int(sim_seed), pose_seed)
        truth = rig.calibration
        t1 = time.perf_counter()
        result = solve_capture(open_capture(folder))
        t2 = time.perf_counter()
    sol = result.solution
    values: dict[str, float] = {"poses": n, "poses_used": len(sol.used), "capture_s": t1 - t0, "solve_s": t2 - t1}
    if sol.calibration is not None:
        cal = sol.calibration
        values["camera_rms_px"] = cal.rms["camera_rms"]
        values["projector_rms_px"] = cal.rms["projector_rms"]
        values["stereo_rms_px"] = cal.rms["stereo_rms"]
        values.update(compare(cal, truth))
        if result.response is not None:
            values["color_mixing_error"] = float(np.abs(result.response.color_mixing - truth.color_mixing).max())
            g = rig.options.projector_gamma
            values["projector_gamma_error_pct"] = float(np.abs(result.response.gamma / g - 1).max() * 100)
        values.update(plane_depth(cal, truth, decode_projector_maps))
    rows = []
    for key, value in values.items():
        target = TARGETS.get(key)
        ok = None if target is None or not np.isfinite(value) else bool(value <= target)
        rows.append({"scene": scene, "metric": key, "value": float(value), "target": target, "ok": ok})
    if sol.problems:
        rows.append(
            {
                "scene": scene,
                "metric": "problems",
                "value": None,
                "target": None,
                "ok": False,
                "note": "; ".join(sol.problems),
            }
        )
    return rows


def format_table(rows: list[dict]) -> str:
    lines = [f"{'metric':<34} {'value':>10} {'target':>8}  ok"]
    for r in rows:
        target = f"<= {r['target']:g}" if r["target"] is not None else ""
        ok = {True: "yes", False: "NO", None: ""}[r["ok"]]
        if r["value"] is None:
            lines.append(f"{r['metric']:<34} {r.get('note', '')}")
            continue
        lines.append(f"{r['metric']:<34} {r['value']:>10.4f} {target:>8}  {ok}")
    return "\n".join(lines)
