"""`slscan bench --accuracy`: every scheme on the virtual rig's scenes against its ground truth.

The rig renders with its default realism (noise, lens blur and defocus, 10 % crosstalk, ambient
light, camera gamma 1.8, shading, specular lobes). Decoding uses the true calibration, including
colour mixing and camera response, as a calibrated rig would have. Per scene and scheme:
coverage = decoded lit pixels / lit pixels; correct = decoded pixels within 0.5 projector px of
the true column / all decoded pixels (a value where the truth has none counts as wrong);
column RMSE over the correct pixels; depth RMSE (mm) over the correct pixels; shots per set.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

FLAG = "--accuracy"
KEY = "accuracy"
HELP = "coverage, correct rate and RMSE of one-shot, two-shot and Gray code on the virtual rig's scenes"

SCENES = ("plane", "face", "colour_panel", "cube", "cylinder", "steps")
SCHEMES = ("one-shot", "two-shot", "graycode")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--accuracy-scenes", default=",".join(SCENES), metavar="LIST", help="scenes (accuracy)")
    parser.add_argument("--accuracy-schemes", default=",".join(SCHEMES), metavar="LIST", help="schemes (accuracy)")


def score(column: np.ndarray, depth: np.ndarray | None, gt_column: np.ndarray, gt_depth: np.ndarray, lit: np.ndarray):
    """(coverage, correct, column_rmse_px, depth_rmse_mm) of one decoded map against the truth."""
    valid = np.isfinite(column)
    err = column - gt_column
    ok = valid & lit & (np.abs(np.nan_to_num(err, nan=np.inf)) <= 0.5)
    coverage = float((valid & lit).sum() / max(1, lit.sum()))
    correct = float(ok.sum() / max(1, valid.sum()))
    col_rmse = float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else float("nan")
    d_rmse = float("nan")
    if depth is not None:
        m = ok & (depth > 0) & (gt_depth > 0)
        if m.any():
            d_rmse = float(np.sqrt(np.mean((depth[m] - gt_depth[m]) ** 2)))
    return coverage, correct, col_rmse, d_rmse


def run(args: argparse.Namespace) -> list[dict]:
    from app.decode.pipeline import EmptyResultWarning, FrameSetDecoder
    from core.patterns import make_patterns
    from drivers.sim.rig import VirtualRig

    warnings.simplefilter("ignore", EmptyResultWarning)
    scenes = [s for s in getattr(args, "accuracy_scenes", ",".join(SCENES)).split(",") if s]
    schemes = [s for s in getattr(args, "accuracy_schemes", ",".join(SCHEMES)).split(",") if s]
    rows = []
    for scene in scenes:
        rig = VirtualRig.from_preset(scene)
        cal = rig.calibration
        cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
        for scheme in schemes:
            ps = make_patterns(scheme, cal.projector_size)
            meta = {"scheme": scheme, "size": list(ps.size), "images": ps.names, **ps.params}
            frames = [rig.render(im) for im in ps.images]
            gt = rig.ground_truth
            res = FrameSetDecoder(scheme, meta, cal, rig.depth_range_mm).decode(frames)
            cov, cor, crm, drm = score(res.stripes.column, res.depth, gt.column, gt.depth, gt.lit)
            rows.append(
                {
                    "scheme": scheme,
                    "scene": scene,
                    "shots": len(frames),
                    "coverage": _num(cov),
                    "correct": _num(cor),
                    "column_rmse_px": _num(crm),
                    "depth_rmse_mm": _num(drm),
                }
            )
    return rows


def _num(x: float) -> float | None:
    """Rounded, or None (JSON null) where there is nothing to measure."""
    return round(x, 4) if np.isfinite(x) else None


def _f(x: float | None, scale: float = 1.0, width: int = 8, prec: int = 2) -> str:
    return f"{'-':>{width}s}" if x is None else f"{scale * x:{width}.{prec}f}"


def format_table(rows: list[dict]) -> str:
    lines = [
        f"{'scheme':9s} {'scene':13s} {'shots':>5s} {'coverage':>9s} {'correct':>8s} "
        f"{'col RMSE px':>11s} {'depth RMSE mm':>13s}"
    ]
    for r in rows:
        lines.append(
            f"{r['scheme']:9s} {r['scene']:13s} {r['shots']:5d} {_f(r['coverage'], 100)}% {_f(r['correct'], 100, 7)}% "
            f"{_f(r['column_rmse_px'], 1, 11, 3)} {_f(r['depth_rmse_mm'], 1, 13, 3)}"
        )
    return "\n".join(lines)
