"""`slscan bench --fusion`: whole models from moving scenes on the virtual rig, against the true surface and poses.

Per scene the rig (default realism) renders the alternating two-shot patterns while the object moves: `turntable`
at 1 deg/frame (362 frames: the last scan is a full turn after the first), `handheld` on its random path. Every
sliding pair is decoded (motion auto), tracked and integrated, then refined (app/fusion/), as `slscan fuse` does a
dump. Then:
mean_mm, rms_mm, p99_mm = the mesh vertices' distance to the true surface; completeness = the share of the true
surface seen lit over the sequence (every 4th frame's truth) within 1 mm of the mesh; drift_deg, drift_mm = the
last scan's pose error (app/fusion/metrics.py); max_err_deg = the largest pose error of any scan; dropped = scans
not in the model after the refinement (app/fusion/refine.py), tracking_dropped = scans that failed registration
while tracking; track_hz, integrate_hz = scans per second of one core's thread CPU time for each step;
scan_hz = the same for making each scan (Fuser.scan: resampling to the pinhole grid, the crop), which tracking needs
first; refine_s = the refinement's CPU time with the integration again; peak_mm_s = the object centre's fastest
speed at 60 frames/s.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

FLAG = "--fusion"
KEY = "fusion"
HELP = "whole models on the virtual rig: turntable and hand-held sequences fused, mesh and poses against the truth"
DEFAULT = False  # needs Open3D (slscan[fusion]) and ~1 min a scene

SCENES = ("turntable", "handheld")
FRAMES = 362
OVERRIDES = {"turntable": {"rotation_deg_per_frame": 1.0}, "handheld": {}}
SEEN_EVERY = 4  # frames whose truth marks the seen surface


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fusion-scenes", default=",".join(SCENES), metavar="LIST", help="scenes (fusion)")
    parser.add_argument("--fusion-size", default="640x480", metavar="WxH", help="camera size (fusion; default 640x480)")
    parser.add_argument("--fusion-frames", type=int, default=FRAMES, metavar="N", help=f"frames (fusion; {FRAMES})")
    parser.add_argument("--fusion-voxel-mm", type=float, default=0.5, metavar="V", help="voxel (fusion; 0.5 mm)")


def measure(scene: str, size: tuple[int, int], frames: int, voxel_mm: float, overrides: dict | None = None) -> dict:
    from app.decode.pipeline import FrameSetDecoder
    from app.fusion import metrics
    from app.fusion.colour import scan_colour
    from app.fusion.fuser import Fuser
    from core.patterns import make_patterns
    from drivers.sim.rig import VirtualRig
    from drivers.sim.truth import seen_by_camera, surface_sample

    ov = dict(OVERRIDES.get(scene, {}))
    ov.update(overrides or {})
    rig = VirtualRig.from_preset(scene, camera_size=size, **ov)
    cal = rig.calibration
    cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
    ps = make_patterns("two-shot", cal.projector_size)
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    dec = FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm, motion="auto")
    fuser = Fuser(cal, rig.depth_range_mm, rig.scene.working_volume_mm, voxel_mm, keep=True)
    truth = surface_sample(rig.moving_shapes)
    prepared = [rig.prepare(img) for img in ps.images]
    seen = np.zeros(len(truth.points), bool)
    recent: list[np.ndarray] = []
    true_poses = []
    first = None
    for k in range(frames):
        recent = [*recent[-2:], rig.render(prepared[k % 2])]
        gt = rig.ground_truth
        if k % SEEN_EVERY == 0:
            seen |= seen_by_camera(
                truth, rig.object_pose(k), gt.depth, gt.lit, cal.camera_matrix, cal.camera_distortion
            )
        if k < 2:
            continue
        prev, older, newest = recent[0], recent[1], recent[2]
        pair = [newest, older] if k % 2 == 0 else [older, newest]
        _, depth = dec.stripes_and_depth(pair, 0 if k % 2 == 0 else 1, prev)
        first = k if first is None else first
        fuser.add(fuser.scan(depth, scan_colour(pair), k + 1))
        true_poses.append(rig.object_pose(first) @ np.linalg.inv(rig.object_pose(k)))
    fuser.refine()  # as slscan fuse does
    P0 = rig.object_pose(first)
    mesh = fuser.mesh()
    V = np.asarray(mesh.vertices)
    V_obj = (V - P0[:3, 3]) @ P0[:3, :3]  # model frame (the camera's at the first scan) -> object frame
    acc = metrics.accuracy(V_obj, truth)
    comp = metrics.completeness(V_obj, np.asarray(mesh.triangles), truth.points[seen])
    model_pts = truth.points @ P0[:3, :3].T + P0[:3, 3]
    errs = [metrics.pose_error(r.pose, t, model_pts[::20]) for r, t in zip(fuser.poses, true_poses, strict=True)]
    drift_deg, drift_mm = metrics.pose_error(fuser.poses[-1].pose, true_poses[-1], model_pts)
    centre = np.mean([s.c for s in rig.moving_shapes], axis=0)
    track = [rig.object_pose(k)[:3, :3] @ centre + rig.object_pose(k)[:3, 3] for k in range(frames)]
    speed = np.linalg.norm(np.diff(track, axis=0), axis=1) * 60.0
    s = fuser.stats
    return {
        "scene": scene,
        "frames": frames,
        "scans": s.scans,
        "dropped": s.dropped,
        "tracking_dropped": s.tracking_dropped,
        "mean_mm": round(acc.mean_mm, 4),
        "rms_mm": round(acc.rms_mm, 4),
        "p99_mm": round(acc.p99_mm, 4),
        "completeness": round(comp, 4),
        "drift_deg": round(drift_deg, 3),
        "drift_mm": round(drift_mm, 3),
        "max_err_deg": round(max(e[0] for e in errs), 3),
        "track_hz": round(1.0 / float(np.mean(s.track_s)), 1),
        "integrate_hz": round(1.0 / float(np.mean(s.integrate_s)), 1) if s.integrate_s else 0.0,
        "scan_hz": round(1.0 / float(np.mean(s.scan_s)), 1) if s.scan_s else 0.0,
        "refine_s": round(s.refine_s, 1),
        "peak_mm_s": round(float(speed.max()), 1) if len(speed) else 0.0,
        "voxel_mm": voxel_mm,
    }


def within_target(row: dict, turntable: dict | None = None) -> bool | None:
    """The issue's targets: turntable mean <= 0.2 mm, RMS <= 0.35 mm, completeness >= 95 %, drift <= 0.5 deg and
    <= 1 mm; hand-held the same accuracy within 1.5x, nothing dropped."""
    if row["scene"] == "turntable":
        return (
            row["mean_mm"] <= 0.2
            and row["rms_mm"] <= 0.35
            and row["completeness"] >= 0.95
            and row["drift_deg"] <= 0.5
            and row["drift_mm"] <= 1.0
        )
    if row["scene"] == "handheld":
        return row["mean_mm"] <= 0.3 and row["rms_mm"] <= 0.525 and row["completeness"] >= 0.95 and row["dropped"] == 0
    return None


def run(args: argparse.Namespace) -> list[dict]:
    import numba

    from app.decode.pipeline import EmptyResultWarning
    from app.fusion.open3d_import import open3d
    from core.patterns import parse_size

    # numba's threads first: Open3D loads an older TBB, with which numba would then refuse its TBB layer (a warning)
    numba.set_num_threads(1)
    open3d()
    warnings.simplefilter("ignore", EmptyResultWarning)
    scenes = [s for s in getattr(args, "fusion_scenes", ",".join(SCENES)).split(",") if s]
    size = parse_size(getattr(args, "fusion_size", "640x480"))
    frames = int(getattr(args, "fusion_frames", FRAMES))
    voxel = float(getattr(args, "fusion_voxel_mm", 0.5))
    rows = []
    for scene in scenes:
        row = measure(scene, size, frames, voxel)
        row["within_target"] = within_target(row)
        rows.append(row)
    return rows


def format_table(rows: list[dict]) -> str:
    lines = [
        f"{'scene':10s} {'scans':>5s} {'drop':>5s} {'mean':>6s} {'rms':>6s} {'p99':>6s} {'compl':>6s} "
        f"{'drift':>6s} {'mm':>6s} {'maxdeg':>6s} {'trackHz':>7s} {'scanHz':>6s} {'intHz':>6s} {'ref_s':>5s} "
        f"{'peak':>5s}  target"
    ]
    for r in rows:
        t = r.get("within_target")
        mark = "" if t is None else ("met" if t else "MISSED")
        lines.append(
            f"{r['scene']:10s} {r['scans']:5d} {r['dropped']:2d}/{r['tracking_dropped']:<2d} "
            f"{r['mean_mm']:6.3f} {r['rms_mm']:6.3f} "
            f"{r['p99_mm']:6.3f} {100 * r['completeness']:5.1f}% {r['drift_deg']:6.2f} {r['drift_mm']:6.2f} "
            f"{r['max_err_deg']:6.2f} {r['track_hz']:7.1f} {r['scan_hz']:6.1f} {r['integrate_hz']:6.1f} "
            f"{r['refine_s']:5.1f} "
            f"{r['peak_mm_s']:5.1f}  {mark}"
        )
    lines.append(
        "(drop: after the refinement / while tracking; "
        "mm: mesh vertices to the true surface; compl: seen true surface within 1 mm of the mesh; drift: the last "
        "scan's pose error, deg and mm; Hz: scans per CPU second, one core; peak: object centre, mm/s)"
    )
    return "\n".join(lines)
