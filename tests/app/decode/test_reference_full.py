"""The fast decoders against the plain numpy reference (app/decode/reference.py) on full 320x240 frames.

The frames, calibrations and settings are the golden cases' (golden/make_golden.py: every rig preset with its
noise, crosstalk and camera gamma, x the three segmentations; 16-bit frames; a mirrored rig; three-channel
two-shot; k = 5; stripe width 2; one-shot). The fast path runs as the product runs it (FrameSetDecoder); the
reference gets only the settings (pattern parameters, colour mixing, camera gamma, the depth range's column
bounds, the segmentation) and builds its own tables. Valid masks must match exactly, columns to 1e-3 px.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from golden.make_golden import CASES, calibration_from

from app.decode import reference
from app.decode.pipeline import FrameSetDecoder
from app.decode.twoshot import TwoShotDecoder, TwoShotParams
from app.decode.windows import LabelParams

GOLDEN = Path(__file__).parent / "golden" / "golden_320x240.npz"
MIN_DECODED = 0.5  # every case decodes most of its pixels: two empty maps would agree and prove nothing


@pytest.fixture(scope="module")
def golden():
    with np.load(GOLDEN) as data:
        yield {k: data[k] for k in data.files}


def _case(golden, name):
    info = json.loads(str(golden[f"{name}/settings"]))
    src = info["frames"]
    frames = [golden[f"{src}/frame{i}"] for i in range(len(info["meta"]["images"]))]
    return info, frames, calibration_from(golden, src)


def _camera_gamma(cal) -> float:
    return float(np.ravel(cal.extra.get("camera_gamma", 1.0))[0])


def _compare(fast: np.ndarray, ref: np.ndarray) -> None:
    vf, vr = np.isfinite(fast), np.isfinite(ref)
    assert vf.mean() > MIN_DECODED, f"the fast path decoded only {vf.mean():.3f} of the pixels"
    if not np.array_equal(vf, vr):
        ys, xs = np.nonzero(vf != vr)
        raise AssertionError(
            f"valid masks differ at {len(ys)} pixels ({(vf & ~vr).sum()} fast only, {(vr & ~vf).sum()} reference "
            f"only), first at (x={xs[0]}, y={ys[0]}): fast {fast[ys[0], xs[0]]}, reference {ref[ys[0], xs[0]]}"
        )
    np.testing.assert_allclose(fast[vf], ref[vr], rtol=0, atol=1e-3)


# The reference specifies the decoder on full-colour frames; the raw Bayer cases (their reconstruction and the
# lacking channel's signs) are pinned by the golden maps and tested against the rig's truth in test_mosaic.py.
TWO_SHOT = [n for n, case in CASES.items() if case[0] == "two-shot" and "bayer" not in case[2]]
ONE_SHOT = [n for n, case in CASES.items() if case[0] == "one-shot"]


def test_the_cases_cover_presets_segmentations_and_variants():
    presets = {CASES[n][1] for n in TWO_SHOT}
    assert presets == {"plane", "face", "colour_panel", "cube", "cylinder", "steps"}
    assert {CASES[n][4] for n in TWO_SHOT} == {"events", "runs", "both"}
    for variant in ("face-16bit", "face-mirrored", "face-rgb", "face-k5", "plane-width2"):
        assert variant in TWO_SHOT


@pytest.mark.parametrize("name", TWO_SHOT)
def test_two_shot_fast_path_matches_the_reference(golden, name):
    info, frames, cal = _case(golden, name)
    dec = FrameSetDecoder("two-shot", info["meta"], cal, tuple(info["depth_range_mm"]), info["segmentation"])
    fast, _ = dec.stripes_and_depth(frames)
    ref = reference.decode_two_shot(
        info["meta"],
        frames[0],
        frames[1],
        mixing=cal.color_mixing,
        gamma=_camera_gamma(cal),
        column_range=dec.triangulator.column_range,
        params=TwoShotParams(segmentation=info["segmentation"]),
    )
    _compare(fast.column, ref.column)
    # the product's decode() of the pair alone (no depth pass) gives the same map
    np.testing.assert_array_equal(dec.decoder.decode(frames[0], frames[1]).column, fast.column)


@pytest.mark.parametrize("name", ONE_SHOT)
def test_one_shot_fast_path_matches_the_reference(golden, name):
    info, frames, cal = _case(golden, name)
    dec = FrameSetDecoder("one-shot", info["meta"], cal, tuple(info["depth_range_mm"]))
    fast, _ = dec.stripes_and_depth(frames)
    ref = reference.decode_one_shot(
        info["meta"],
        frames[0],
        mixing=cal.color_mixing,
        gamma=_camera_gamma(cal),
        column_range=dec.triangulator.column_range,
    )
    _compare(fast.column, ref.column)


def test_the_mirrored_rig_is_decoded_mirrored(golden):
    # the mirrored case must exercise the flip: its columns fall as x grows, and read unflipped the stripes come in
    # reverse order (a two-shot sequence holds every one-bit walk, so reversed windows still match by chance, but
    # rarely survive confirmation, the copy vote and the depth range)
    info, frames, cal = _case(golden, "face-mirrored")
    dec = FrameSetDecoder("two-shot", info["meta"], cal, tuple(info["depth_range_mm"]), info["segmentation"])
    lo, hi = dec.triangulator.column_range
    assert reference.columns_run_backwards((lo, hi))
    unflipped = reference.label_rows(
        *reference.classify_two_shot(
            frames[0],
            frames[1],
            *reference.linearisation(256, _camera_gamma(cal)),
            reference.unmixing_rows(cal.color_mixing, info["meta"]["channels"]),
            TwoShotParams(),
        ),
        reference.two_shot_pattern(info["meta"], info["meta"]["size"][0]),
        TwoShotParams().label,
        (lo, hi),
        events=False,
    )
    flipped = reference.decode_two_shot(
        info["meta"], *frames, mixing=cal.color_mixing, gamma=_camera_gamma(cal), column_range=(lo, hi)
    )
    assert flipped.valid.mean() > MIN_DECODED
    assert unflipped.valid.mean() < 0.5 * flipped.valid.mean()


@pytest.mark.parametrize(
    "name, label, response",
    [
        ("cube-runs", LabelParams(edges=False), False),  # nodes at stripe centres (ties at the chain's span ends)
        ("face-16bit", LabelParams(), True),  # a measured per-channel camera response instead of a gamma
    ],
)
def test_settings_off_the_product_default_match_the_reference(golden, name, label, response):
    info, frames, cal = _case(golden, name)
    dec = FrameSetDecoder("two-shot", info["meta"], cal, tuple(info["depth_range_mm"]), info["segmentation"])
    params = TwoShotParams(segmentation=info["segmentation"], label=label)
    levels = 65536 if frames[0].dtype == np.uint16 else 256
    raw = np.linspace(0.0, 1.0, levels)
    curve = np.stack([raw**2.1, raw**2.2, raw**2.3]) if response else None
    gamma = _camera_gamma(cal)
    rng = dec.triangulator.column_range
    fast = TwoShotDecoder(info["meta"], info["meta"]["size"][0], cal.color_mixing, rng, params, gamma, curve)
    ref = reference.decode_two_shot(
        info["meta"], *frames, mixing=cal.color_mixing, gamma=gamma, response=curve, column_range=rng, params=params
    )
    _compare(fast.decode(*frames).column, ref.column)
