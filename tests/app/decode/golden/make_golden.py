"""Write the decoder's golden maps: `python tests/app/decode/golden/make_golden.py` (with `--missing`: only the
cases not yet in the file, the stored ones kept as they are; with `--redecode NAME,NAME`: those cases' maps
decoded again from their stored frames, everything else kept).

Each case is a frame set rendered by the virtual rig at 320x240 (the frames are stored, so a change to the
renderer never moves a golden), its calibration, patterns and decoder settings, and the fast path's column
and depth maps. `test_golden.py` decodes the stored frames again and requires the same bits. Rewrite the
file only for a reviewed change of the decoder's output, and say in the commit what moved and why.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[4]
OUT = Path(__file__).with_name("golden_320x240.npz")
SIZE = {"camera_size": (320, 240), "projector_size": (512, 384)}
PRESETS = ("plane", "face", "colour_panel", "cube", "cylinder", "steps")
SEGMENTATIONS = ("events", "runs", "both")

# name -> (scheme, preset, rig overrides, pattern options, segmentation or None)
CASES: dict[str, tuple[str, str, dict, dict, str | None]] = {
    **{f"{p}-{s}": ("two-shot", p, {}, {}, s) for p in PRESETS for s in SEGMENTATIONS},
    "face-16bit": ("two-shot", "face", {"bit_depth": 16}, {}, "runs"),
    "face-mirrored": ("two-shot", "face", {"projector_roll_deg": 180.4}, {}, "runs"),
    "face-rgb": ("two-shot", "face", {}, {"channels": "RGB"}, "runs"),
    "face-k5": ("two-shot", "face", {}, {"k": 5}, "runs"),
    "plane-width2": ("two-shot", "plane", {}, {"stripe_width": 2}, "runs"),
    "face-oneshot": ("one-shot", "face", {}, {}, None),
    "cube-oneshot": ("one-shot", "cube", {}, {}, None),
    # raw Bayer mosaics (one channel a frame), reconstructed and given the lacking channel's signs from the G edges
    "face-rggb": ("two-shot", "face", {"bayer": "RGGB"}, {}, "runs"),
    "face-rggb-both": ("two-shot", "face", {"bayer": "RGGB"}, {}, "both"),
    "face-rggb-12bit": ("two-shot", "face", {"bayer": "RGGB", "bit_depth": 12}, {}, "runs"),
    "colour_panel-rggb": ("two-shot", "colour_panel", {"bayer": "RGGB"}, {}, "runs"),
    "cube-gbrg": ("two-shot", "cube", {"bayer": "GBRG"}, {}, "runs"),
}

CAL_FIELDS = (
    "camera_size",
    "camera_matrix",
    "camera_distortion",
    "projector_size",
    "projector_matrix",
    "projector_distortion",
    "R",
    "T",
)


def render_case(scheme: str, preset: str, overrides: dict, options: dict) -> tuple[list[np.ndarray], object, dict]:
    from app.patterns import make_patterns
    from drivers.sim.rig import VirtualRig

    rig = VirtualRig.from_preset(preset, **{**SIZE, **overrides})
    cal = rig.calibration
    ps = make_patterns(scheme, cal.projector_size, **options)
    meta = {"scheme": scheme, "size": list(ps.size), "images": ps.names, **ps.params}
    frames = [rig.render(im) for im in ps.images]
    settings = {"meta": meta, "depth_range_mm": list(rig.depth_range_mm)}
    if rig.mosaic is not None:
        settings["mosaic"] = rig.mosaic
    return frames, cal, settings


def decode_case(scheme: str, frames: list[np.ndarray], cal, settings: dict, segmentation: str | None):
    from app.decode.pipeline import FrameSetDecoder

    dec = FrameSetDecoder(
        scheme, settings["meta"], cal, tuple(settings["depth_range_mm"]), segmentation, mosaic=settings.get("mosaic")
    )
    sm, depth = dec.stripes_and_depth(frames)
    return sm.column, depth


def calibration_arrays(cal) -> dict[str, np.ndarray]:
    out = {f"cal_{f}": np.asarray(getattr(cal, f)) for f in CAL_FIELDS}
    out["cal_color_mixing"] = np.asarray(cal.color_mixing)
    out["cal_extra"] = np.asarray(json.dumps({k: float(v) for k, v in cal.extra.items()}))
    return out


def calibration_from(data, name: str):
    from calibration.model import Calibration

    fields = {f: data[f"{name}/cal_{f}"] for f in CAL_FIELDS}
    extra = json.loads(str(data[f"{name}/cal_extra"]))
    return Calibration(**fields, color_mixing=data[f"{name}/cal_color_mixing"], extra=extra)


def pack_bits(a: np.ndarray) -> np.ndarray:
    """A float32 map as its bit patterns' differences along each row, split into byte planes (uint8 (4, H * W)):
    smooth maps then compress to about half (unpack_bits inverts it exactly)."""
    bits = a.astype(np.float32).view(np.uint32)
    delta = np.diff(bits.astype(np.int64), axis=1, prepend=0).astype(np.uint32)
    return np.ascontiguousarray(delta.view(np.uint8).reshape(-1, 4).T)


def unpack_bits(planes: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    delta = np.ascontiguousarray(planes.T).view(np.uint32).reshape(shape)
    return np.cumsum(delta, axis=1, dtype=np.uint32).view(np.float32)


def redecode(names: list[str]) -> int:
    """The named cases' maps decoded again from their stored frames and calibrations (a reviewed decoder change)."""
    with np.load(OUT) as data:
        arrays = {k: data[k] for k in data.files}
    for name in names:
        if f"{name}/settings" not in arrays:
            print(f"make_golden: no case {name!r} in {OUT.name}", file=sys.stderr)
            return 2
        info = json.loads(str(arrays[f"{name}/settings"]))
        src = info["frames"]
        frames = [arrays[f"{src}/frame{i}"] for i in range(len(info["meta"]["images"]))]
        column, depth = decode_case(info["scheme"], frames, calibration_from(arrays, src), info, info["segmentation"])
        arrays[f"{name}/column"] = pack_bits(column)
        if f"{name}/depth" in arrays:
            arrays[f"{name}/depth"] = pack_bits(depth)
        print(f"{name}: {np.isfinite(column).mean():.3f} of the pixels decoded")
    np.savez_compressed(OUT, **arrays)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e6:.1f} MB)")
    return 0


def main(argv: list[str]) -> int:
    sys.path.insert(0, str(ROOT))
    if "--redecode" in argv:
        return redecode(argv[argv.index("--redecode") + 1].split(","))
    arrays: dict[str, np.ndarray] = {}
    if "--missing" in argv:
        with np.load(OUT) as data:
            arrays = {k: data[k] for k in data.files}
    done = {k.split("/")[0] for k in arrays if k.endswith("/settings")}
    sets = len({k.split("/")[0] for k in arrays if k.endswith("/frame0")})
    rendered: dict[str, tuple] = {}
    for name, (scheme, preset, overrides, options, seg) in CASES.items():
        if name in done:
            continue
        source = json.dumps([scheme, preset, overrides, options], sort_keys=True)
        if source not in rendered:
            rendered[source] = (f"set{sets + len(rendered)}", *render_case(scheme, preset, overrides, options))
            key, frames, cal, _ = rendered[source]
            for i, f in enumerate(frames):
                arrays[f"{key}/frame{i}"] = f
            arrays.update({f"{key}/{k}": v for k, v in calibration_arrays(cal).items()})
        key, frames, cal, settings = rendered[source]
        column, depth = decode_case(scheme, frames, cal, settings, seg)
        info = {**settings, "scheme": scheme, "segmentation": seg, "frames": key, "shape": list(column.shape)}
        arrays[f"{name}/settings"] = np.asarray(json.dumps(info))
        arrays[f"{name}/column"] = pack_bits(column)
        if seg in (None, "runs"):  # depth is the column triangulated: once per frame set is enough
            arrays[f"{name}/depth"] = pack_bits(depth)
        print(f"{name}: {np.isfinite(column).mean():.3f} of the pixels decoded")
    np.savez_compressed(OUT, **arrays)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
