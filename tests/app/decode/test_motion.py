"""Moving scenes: the newest frame of a sliding two-shot pair decoded against the rig's truth of that frame."""

from __future__ import annotations

import numpy as np
import pytest

from app.bench.motion import score
from app.decode.motion import MotionParams, MotionRepair, check_motion_mode, repair_reference
from app.decode.pipeline import FrameSetDecoder
from app.errors import InputError
from app.framesets import group_frame_sets
from app.patterns import make_patterns
from drivers.sim.rig import VirtualRig

SMALL = {"camera_size": (320, 240), "projector_size": (512, 384)}


def sequence(scene: str, small: bool = True, **overrides):
    """A rig (small, else the bench's 640x480 with its projector), four frames of the alternating patterns 0, 1, 0, 1
    rendered while it moves, the truth after each frame, and a two-shot FrameSetDecoder per motion mode (and
    "make": a decoder for given MotionParams)."""
    rig = VirtualRig.from_preset(scene, **{**(SMALL if small else {"camera_size": (640, 480)}), **overrides})
    cal = rig.calibration
    cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
    ps = make_patterns("two-shot", cal.projector_size)
    frames, truths = [], []
    for i in range(4):
        frames.append(rig.render(ps.images[i % 2]))
        truths.append((rig.ground_truth.depth.copy(), rig.ground_truth.lit.copy()))
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    decoders = {m: FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm, motion=m) for m in ("auto", "off")}
    decoders["make"] = lambda params: FrameSetDecoder(
        "two-shot", meta, cal, rig.depth_range_mm, motion="auto", motion_params=params
    )
    return frames, truths, decoders


def newest_pairs(frames, truths):
    """The sliding pairs (frames 1-2: newest is pattern 0; 2-3: pattern 1): (pair in pattern order, newest's
    pattern index, the frame before the pair, the newest frame's truth)."""
    return [([frames[2], frames[1]], 0, frames[0], truths[2]), ([frames[2], frames[3]], 1, frames[1], truths[3])]


@pytest.fixture(scope="module")
def moving_face():
    return sequence("face", motion_mm_per_frame=(8.0, 0.0, 0.0))


@pytest.mark.parametrize(
    ("scene", "motion", "moving"),
    [
        ("cube", {"motion_mm_per_frame": (4.0, 0.0, 0.0)}, 0.2),
        # (few pixels move: most rows' work spans only part of the row, cut off at one end of it or at neither)
        ("turntable", {"rotation_deg_per_frame": 2.0}, 0.02),
    ],
)
@pytest.mark.parametrize("bit_depth", [8, 16])
def test_the_compiled_repair_is_its_numpy_statement(bit_depth, scene, motion, moving):
    frames, _, decoders = sequence(scene, bit_depth=bit_depth, **motion)
    luts = decoders["auto"].decoder.luts(frames[0].dtype)
    fast, n_fast = MotionRepair(luts, "GB", MotionParams())(frames[3], frames[2], frames[1])
    ref, n_ref = repair_reference(frames[3], frames[2], frames[1], luts, "GB", MotionParams())
    assert n_fast == n_ref > moving * frames[0].shape[0] * frames[0].shape[1]
    np.testing.assert_array_equal(fast, ref)


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_separate_moving_regions_of_one_row_repair_as_the_numpy_statement(bit_depth):
    """Two patches of a still scene moved along the row, far apart in the same rows (two segments of a row), and a
    band moved over the whole width (a dense row): the compiled repair is its numpy statement there."""
    frames, _, decoders = sequence("face", bit_depth=bit_depth)
    newest = frames[3].copy()
    for x0 in (90, 230):  # (lit, farther apart than the segments' join, each wider than a window)
        newest[60:90, x0 : x0 + 30] = np.roll(frames[3][60:90, x0 : x0 + 30], 4, axis=1)
    newest[150:160] = np.roll(frames[3][150:160], 6, axis=1)
    luts = decoders["auto"].decoder.luts(frames[0].dtype)
    fast, n_fast = MotionRepair(luts, "GB", MotionParams())(newest, frames[2], frames[1])
    ref, n_ref = repair_reference(newest, frames[2], frames[1], luts, "GB", MotionParams())
    assert n_fast == n_ref
    moved = np.any(fast != frames[2], axis=2)
    assert moved[60:90, 90:120].any() and moved[60:90, 230:260].any() and not moved[60:90, 140:220].any()
    assert moved[150:160].mean() > 0.3
    np.testing.assert_array_equal(fast, ref)


@pytest.mark.parametrize("scene", ["face", "colour_panel", "cube"])
def test_a_still_scene_decodes_bit_for_bit_as_the_pair(scene):
    frames, truths, decoders = sequence(scene)
    for pair, newest, previous, _ in newest_pairs(frames, truths):
        sm_auto, depth_auto = decoders["auto"].stripes_and_depth(pair, newest, previous)
        sm_off, depth_off = decoders["off"].stripes_and_depth(pair)
        assert sm_auto.info["moving"] == 0.0
        np.testing.assert_array_equal(sm_auto.column, sm_off.column)
        np.testing.assert_array_equal(depth_auto, depth_off)


def test_at_hand_speed_the_newest_frame_decodes_right(moving_face):
    """8 mm/frame (0.5 m/s at 60 Hz): the pair's sign alone loses coverage and makes gross errors; the newest
    frame decoded where the scene moved is right against its own truth."""
    frames, truths, decoders = moving_face
    for pair, newest, previous, (truth_depth, lit) in newest_pairs(frames, truths):
        sm, depth = decoders["auto"].stripes_and_depth(pair, newest, previous)
        coverage, correct, gross = score(depth, truth_depth, lit)
        off = score(decoders["off"].stripes_and_depth(pair)[1], truth_depth, lit)
        assert sm.info["moving"] > 0.3
        # (at 320x240 a camera pixel spans twice the depth it does at 640x480: a still face is 91 % within 1 mm)
        assert coverage >= 0.85 and coverage >= off[0] + 0.25, (coverage, off)
        assert correct >= 0.92 and correct >= off[1] + 0.15, (correct, off)
        assert gross <= 0.008 and off[2] >= 4 * gross, (gross, off)  # (the pair alone: wrong stripe copies)


def test_a_turntable_at_2_degrees_a_frame_meets_its_target():
    """The bench's turntable row at 2 deg/frame (640x480: at 320x240 a pixel spans too much depth for 1 mm): the
    bust's surface slides along itself, so few pixels count as moving, and those decode from the newest frame
    within 1 mm of its truth where the pair's sign alone has more errors."""
    frames, truths, decoders = sequence("turntable", small=False, rotation_deg_per_frame=2.0)
    auto, off = [], []
    for pair, newest, previous, (truth_depth, lit) in newest_pairs(frames, truths):
        sm, depth = decoders["auto"].stripes_and_depth(pair, newest, previous)
        auto.append(score(depth, truth_depth, lit))
        off.append(score(decoders["off"].stripes_and_depth(pair)[1], truth_depth, lit))
        assert 0.02 < sm.info["moving"] < 0.15
    (coverage, correct, gross), (_, correct_off, gross_off) = np.mean(auto, axis=0), np.mean(off, axis=0)
    assert coverage >= 0.90 and correct >= 0.995, (auto, off)
    assert correct > correct_off + 0.001 and gross <= gross_off, (auto, off)


def mean_figures(frames, truths, decoders, params):
    """The sliding pairs' mean (coverage, correct, gross) decoded with motion auto and the given MotionParams."""
    dec = decoders["make"](params)
    figures = []
    for pair, newest, previous, (truth_depth, lit) in newest_pairs(frames, truths):
        figures.append(score(dec.stripes_and_depth(pair, newest, previous)[1], truth_depth, lit))
    return np.mean(figures, axis=0)


@pytest.mark.parametrize("scene", ["cube", "colour_panel"])
def test_saturated_moving_surfaces_take_both_levels_from_the_pairs_local_means(scene):
    """8 mm/frame at 640x480 (saturated stickers and patches, where the newest frame's own envelope is weakest):
    where the two frames' local means agree they give the pair's sum of both levels, and cover more than the
    envelope alone at the same correct rate; on the cube that reaches 0.85 x its still coverage."""
    frames, truths, decoders = sequence(scene, small=False, motion_mm_per_frame=(8.0, 0.0, 0.0))
    means = mean_figures(frames, truths, decoders, MotionParams())
    envelope = mean_figures(frames, truths, decoders, MotionParams(mean_share=-1.0, mean_floor=-1.0))  # (never)
    assert means[0] >= envelope[0] + 0.01 and means[1] >= envelope[1] - 0.001, (means, envelope)
    assert means[2] <= 0.002, means
    if scene == "cube":
        still_frames, still_truths, still_decoders = sequence(scene, small=False)
        still = mean_figures(still_frames, still_truths, still_decoders, MotionParams())
        assert means[0] >= 0.85 * still[0] and means[1] >= 0.99, (means, still)


def test_without_the_frame_before_the_pair_decodes_as_it_is(moving_face):
    frames, _, decoders = moving_face
    pair = [frames[2], frames[3]]
    sm, depth = decoders["auto"].stripes_and_depth(pair, 1, None)
    _, depth_off = decoders["off"].stripes_and_depth(pair)
    assert "moving" not in sm.info
    np.testing.assert_array_equal(depth, depth_off)


def test_decode_checks_the_previous_frame(moving_face):
    frames, _, decoders = moving_face
    with pytest.raises(InputError, match="previous frame"):
        decoders["auto"].decode([frames[2], frames[3]], newest=1, previous=frames[1][:100])


def test_motion_modes():
    assert check_motion_mode("auto", "x") == "auto"
    assert check_motion_mode(False, "x") == "off"  # (YAML reads a bare off as false)
    with pytest.raises(InputError, match=r"cfg\.yaml: key 'scheme\.motion': motion must be one of auto, off"):
        check_motion_mode("fast", "cfg.yaml: key 'scheme.motion'")


def test_sliding_pairs_know_the_frame_before_them():
    tags = [(10, 0), (11, 1), (12, 0), (13, 1), (15, 0), (16, 1)]
    sets, _ = group_frame_sets(tags, "two-shot", 2)
    # pairs 0-1 (none before), 1-2 (frame 0 saw pattern 0, the newest's), 2-3 (frame 1), then after the gap 4-5
    assert [(s.indices, s.newest_index, s.previous) for s in sets] == [
        ((0, 1), 1, None),
        ((2, 1), 0, 0),
        ((2, 3), 1, 1),
        ((4, 5), 1, None),
    ]


def test_offline_decode_of_a_moving_dump_gives_the_newest_frames_geometry(tmp_path, run_cli):
    """`slscan sim render` a moving face (two pattern cycles), `slscan decode` it with motion auto and off: the
    sliding pairs that have a frame before them decode to their newest frame's truth."""
    from app.imageio import read_float_tiff

    dump = tmp_path / "moving"
    r = run_cli(
        "sim", "render", "--scene", "face", "--scheme", "two-shot", "--camera-size", "320x240",
        "--set", "projector_size=[512, 384]", "--set", "motion_mm_per_frame=[8, 0, 0]", "--cycles", "2",
        "--out", dump,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    figures = {}
    for mode in ("auto", "off"):
        out = tmp_path / mode
        r = run_cli("decode", dump, "--out", out, "--workers", "1", "--motion", mode)
        assert r.returncode == 0, r.stderr
        assert "decoded 3 two-shot frame set(s)" in r.stdout
        # sets: frames (0, 1), (2, 1), (2, 3); the last two have a frame before them, their newest are 2 and 3
        figures[mode] = []
        for n, newest in ((1, 2), (2, 3)):
            truth = dump / "ground_truth" / "frames" / f"{newest:06d}"
            lit = read_float_tiff(truth / "depth.tiff") > 0  # (visible; lit is close to it on this scene)
            depth = read_float_tiff(out / f"depth_{n:06d}.tiff")
            figures[mode].append(score(depth, read_float_tiff(truth / "depth.tiff"), lit))
    for (cov, cor, gross), (cov_off, cor_off, gross_off) in zip(figures["auto"], figures["off"], strict=True):
        assert cov >= cov_off + 0.2 and cor >= cor_off + 0.1, figures
        assert gross <= 0.01 and gross_off >= 3 * gross, figures


def test_the_bench_selects_motions_by_their_labels():
    from app.bench.motion import selected_motions

    assert [label for label, _ in selected_motions("face", "x 8 mm,z 2 mm")] == ["still", "x 8 mm", "z 2 mm"]
    assert [label for label, _ in selected_motions("turntable", "x 8 mm,turn 2 deg")] == ["still", "turn 2 deg"]
    assert len(selected_motions("cube", "")) == 10
    with pytest.raises(InputError, match=r"--motion-motions: unknown motion 'x 3 mm'"):
        selected_motions("face", "x 3 mm")
