"""`slscan bench --accuracy`: every scheme on the virtual rig's scenes against its ground truth.

The rig renders with its default realism (noise, lens blur and defocus, 10 % crosstalk, ambient
light, camera gamma 1.8, shading, specular lobes). Decoding uses the true calibration, including
colour mixing and camera response, as a calibrated rig would have. Per scene and scheme:
coverage = decoded lit pixels / lit pixels; correct = decoded pixels within 0.5 projector px of
the true column / all decoded pixels (a value where the truth has none counts as wrong);
column RMSE over the correct pixels; depth RMSE (mm) over the correct pixels; within 1 mm = decoded pixels
whose depth is within 1 mm of the truth / decoded pixels on a surface; shots per set.

Cameras (two-shot): `3-CCD` (one colour per pixel, as the paper's camera: every scheme's rows), `RGGB raw`
(the same exposure through an RGGB mosaic, decoded from the raw frame: app/decode/mosaic.py) and `RGGB
demosaiced` (that raw frame demosaiced by OpenCV's bilinear Bayer conversion, as a photographic pipeline
delivers it), at 8 and 12 bits; `YUYV 4:2:2` and `MJPEG 4:2:0` (a webcam's colour, subsampled across the
rows: core/chroma.py; 8 bits), under the bench's one-pixel stripes.
"""

from __future__ import annotations

import argparse
import warnings

import cv2
import numpy as np

from core.chroma import subsample_chroma
from core.errors import InputError
from core.mosaic import sample_mosaic

FLAG = "--accuracy"
KEY = "accuracy"
HELP = "coverage, correct rate and RMSE of one-shot, two-shot and Gray code on the virtual rig's scenes"

SCENES = ("plane", "face", "colour_panel", "cube", "cylinder", "steps")
SCHEMES = ("one-shot", "two-shot", "graycode")
CAMERAS = ("3ccd", "rggb-raw", "rggb-demosaiced", "yuyv-422", "mjpeg-420")
CAMERA_NAMES = {
    "3ccd": "3-CCD",
    "rggb-raw": "RGGB raw",
    "rggb-demosaiced": "RGGB demosaiced",
    "yuyv-422": "YUYV 4:2:2",
    "mjpeg-420": "MJPEG 4:2:0",
}
CHROMA_OF = {"yuyv-422": "4:2:2", "mjpeg-420": "4:2:0"}  # (webcam colour: 8-bit only)
BITS = (8, 12)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--accuracy-scenes", default=",".join(SCENES), metavar="LIST", help="scenes (accuracy)")
    parser.add_argument("--accuracy-schemes", default=",".join(SCHEMES), metavar="LIST", help="schemes (accuracy)")
    parser.add_argument(
        "--accuracy-cameras", default=",".join(CAMERAS), metavar="LIST", help="two-shot cameras (accuracy)"
    )
    parser.add_argument(
        "--accuracy-bits", default=",".join(map(str, BITS)), metavar="LIST", help="two-shot camera bits (accuracy)"
    )


def score(column: np.ndarray, depth: np.ndarray | None, gt_column: np.ndarray, gt_depth: np.ndarray, lit: np.ndarray):
    """(coverage, correct, column_rmse_px, depth_rmse_mm) of one decoded map against the truth."""
    return _score(column, depth, gt_column, gt_depth, lit)[:4]


def within_1mm(depth: np.ndarray | None, gt_depth: np.ndarray) -> float:
    """The share of decoded depths (on a surface) within 1 mm of the truth; NaN without depth."""
    if depth is None:
        return float("nan")
    m = (depth > 0) & (gt_depth > 0)
    return float((np.abs(depth[m] - gt_depth[m]) <= 1.0).mean()) if m.any() else float("nan")


def _score(column, depth, gt_column, gt_depth, lit):
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
    return coverage, correct, col_rmse, d_rmse, within_1mm(depth, gt_depth)


def run(args: argparse.Namespace) -> list[dict]:
    from app.decode.pipeline import EmptyResultWarning, FrameSetDecoder
    from core.patterns import make_patterns
    from drivers.sim.rig import VirtualRig

    warnings.simplefilter("ignore", EmptyResultWarning)
    scenes = [s for s in getattr(args, "accuracy_scenes", ",".join(SCENES)).split(",") if s]
    schemes = [s for s in getattr(args, "accuracy_schemes", ",".join(SCHEMES)).split(",") if s]
    cameras = [c for c in getattr(args, "accuracy_cameras", ",".join(CAMERAS)).split(",") if c]
    bits = [int(b) for b in str(getattr(args, "accuracy_bits", ",".join(map(str, BITS)))).split(",") if b]
    for c in cameras:
        if c not in CAMERAS:
            raise InputError(f"--accuracy-cameras: unknown camera {c!r} (choose {', '.join(CAMERAS)})")
    for b in bits:
        if b not in (8, 12, 16):
            raise InputError(f"--accuracy-bits: {b} (choose 8, 12 or 16)")
    rows = []
    for scene in scenes:
        for depth in sorted(set(bits) | {8}):
            # every scheme at 8 bits on the 3-CCD camera; the two-shot camera variants at each depth asked
            if depth != 8 and "two-shot" not in schemes:
                continue
            rig = VirtualRig.from_preset(scene, bit_depth=depth)
            cal = rig.calibration
            cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
            for scheme in schemes if depth == 8 else ["two-shot"]:
                ps = make_patterns(scheme, cal.projector_size)
                meta = {"scheme": scheme, "size": list(ps.size), "images": ps.names, **ps.params}
                frames = [rig.render(im) for im in ps.images]
                gt = rig.ground_truth
                variants = ["3ccd"]  # every scheme at 8 bits: the figure the other cameras are read against
                if scheme == "two-shot" and depth in bits:
                    variants = [c for c in cameras if c != "3ccd" or depth != 8]
                    variants = ["3ccd", *variants] if depth == 8 else variants
                    variants = [c for c in variants if depth == 8 or c not in CHROMA_OF]
                for camera in variants:
                    mosaic = "RGGB" if camera.startswith("rggb") else None
                    shown = [camera_frame(f, camera) for f in frames]
                    dec = FrameSetDecoder(scheme, meta, cal, rig.depth_range_mm, mosaic=mosaic)
                    res = dec.decode(shown)
                    cov, cor, crm, drm, w1 = _score(res.stripes.column, res.depth, gt.column, gt.depth, gt.lit)
                    rows.append(
                        {
                            "scheme": scheme,
                            "scene": scene,
                            "camera": CAMERA_NAMES[camera],
                            "bits": depth,
                            "shots": len(frames),
                            "coverage": _num(cov),
                            "correct": _num(cor),
                            "column_rmse_px": _num(crm),
                            "depth_rmse_mm": _num(drm),
                            "within_1mm": _num(w1),
                        }
                    )
    return rows


def camera_frame(image: np.ndarray, camera: str) -> np.ndarray:
    """What a camera delivers of an RGB exposure: as it is (3-CCD), its RGGB mosaic (raw), that mosaic
    demosaiced by OpenCV (bilinear), or its colour subsampled (YUYV, MJPEG)."""
    if camera == "3ccd":
        return image
    if camera in CHROMA_OF:
        return subsample_chroma(image, CHROMA_OF[camera])
    raw = sample_mosaic(image, "RGGB")
    return raw if camera == "rggb-raw" else cv2.cvtColor(raw, cv2.COLOR_BayerRGGB2RGB)


def _num(x: float) -> float | None:
    """Rounded, or None (JSON null) where there is nothing to measure."""
    return round(x, 4) if np.isfinite(x) else None


def _f(x: float | None, scale: float = 1.0, width: int = 8, prec: int = 2) -> str:
    return f"{'-':>{width}s}" if x is None else f"{scale * x:{width}.{prec}f}"


def format_table(rows: list[dict]) -> str:
    lines = [
        f"{'scheme':9s} {'scene':13s} {'camera':16s} {'bits':>4s} {'shots':>5s} {'coverage':>9s} {'correct':>8s} "
        f"{'col RMSE px':>11s} {'depth RMSE mm':>13s} {'within 1 mm':>11s}"
    ]
    for r in rows:
        lines.append(
            f"{r['scheme']:9s} {r['scene']:13s} {r.get('camera', '3-CCD'):16s} {r.get('bits', 8):4d} {r['shots']:5d} "
            f"{_f(r['coverage'], 100)}% {_f(r['correct'], 100, 7)}% "
            f"{_f(r['column_rmse_px'], 1, 11, 3)} {_f(r['depth_rmse_mm'], 1, 13, 3)} "
            f"{_f(r.get('within_1mm'), 100, 10)}%"
        )
    return "\n".join(lines)
