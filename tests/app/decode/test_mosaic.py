"""Raw Bayer frames: the reconstruction along the stripes, and two-shot depth from raw mosaics against the
virtual rig's ground truth, for every mosaic order and 8 and 12 bits."""

from __future__ import annotations

import itertools
import warnings
from dataclasses import replace

import cv2
import numpy as np
import pytest

from app.bench.accuracy import score, within_1mm
from app.decode.colour import unmixing_matrix
from app.decode.fast.lacking_edges import lacking_edges
from app.decode.mosaic import NO_LEAKS, mosaic_leaks, stripe_rgb
from app.decode.mosaic_signs import lacking_signs
from app.decode.pipeline import EmptyResultWarning, FrameSetDecoder
from core.errors import InputError
from core.mosaic import MOSAICS, mosaic_name, sample_mosaic, site_codes
from core.patterns import make_patterns
from drivers.sim.rig import VirtualRig

# 320x240 under a 512x384 projector keeps a stripe ~2 camera pixels wide, as at the bench's 640x480 x 1024x768
SIZES = {"camera_size": (320, 240), "projector_size": (512, 384)}


@pytest.mark.parametrize("mosaic", MOSAICS)
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_vertical_stripes_keep_g_and_each_columns_own_channel_exactly(mosaic, dtype) -> None:
    rng = np.random.default_rng(3)
    top = np.iinfo(dtype).max
    columns = rng.integers(0, top + 1, (1, 40, 3)).astype(dtype)
    image = np.repeat(columns, 30, axis=0)  # constant down every column, as the projected stripes
    rgb = stripe_rgb(sample_mosaic(image, mosaic), mosaic)
    assert rgb.dtype == dtype and rgb.shape == image.shape
    assert np.array_equal(rgb[..., 1], image[..., 1])  # G: every pixel, from its own column only
    for channel in (0, 2):
        held = next(x for x in (0, 1) if "RGB"[channel] in mosaic[x] + mosaic[2 + x])
        assert np.array_equal(rgb[:, held::2, channel], image[:, held::2, channel])


@pytest.mark.parametrize("mosaic", MOSAICS)
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_the_lacking_channel_carries_its_columns_own_g_leak(mosaic, dtype) -> None:
    # R and B = a constant plus k times G, G different in every column (as under the stripes): with the leaks,
    # what is interpolated across the row (c - k G) is constant, so the lacking channel comes back to a level
    rng = np.random.default_rng(5)
    top = np.iinfo(dtype).max
    k_r, k_b = 0.09375, 0.078125  # (24 / 256, 20 / 256: exact in the fixed point)
    g = rng.integers(0, top + 1, 40).astype(np.float64)
    columns = np.stack([0.2 * top + k_r * g, g, 0.3 * top + k_b * g], axis=-1)
    image = np.repeat(np.rint(columns)[None], 30, axis=0).astype(dtype)
    raw = sample_mosaic(image, mosaic)
    err = np.abs(stripe_rgb(raw, mosaic, leaks=(k_r, k_b)).astype(np.int64) - image)
    assert err.max() <= 1 and not err[..., 1].any()
    # without them the lacking channel carries its neighbours' G leaks (of other stripes)
    assert np.abs(stripe_rgb(raw, mosaic).astype(np.int64) - image).max() > 0.02 * top


def test_the_leaks_cancel_g_in_the_unmixed_channel() -> None:
    assert mosaic_leaks(None) == NO_LEAKS
    rig = VirtualRig.from_preset("plane", ideal=True, **SIZES)
    mixing = VirtualRig.from_preset("plane", **SIZES).calibration.color_mixing
    assert mosaic_leaks(rig.calibration.color_mixing) == NO_LEAKS  # (no crosstalk)
    U = unmixing_matrix(mixing).astype(np.float64)
    k_r, k_b = mosaic_leaks(mixing)
    assert 0.05 < k_r < 0.2 and 0.05 < k_b < 0.2  # the rig's ~10 % leaks
    # camera c = k_c G unmixes to no primary c at all: the fill's k G[x] adds nothing of column x's G stripe
    assert abs(U[0, 1] + U[0, 0] * k_r) < 1e-6 and abs(U[2, 1] + U[2, 2] * k_b) < 1e-6


def test_flat_colour_reconstructs_to_itself() -> None:
    image = np.empty((16, 20, 3), np.uint16)
    image[...] = (40000, 20000, 9000)
    for mosaic in MOSAICS:
        assert np.array_equal(stripe_rgb(sample_mosaic(image, mosaic), mosaic), image)


def test_unknown_mosaic_names_the_field() -> None:
    with pytest.raises(InputError, match=r"sim\.bayer: .RGB. is not a Bayer mosaic"):
        mosaic_name("RGB", "sim.bayer")
    assert mosaic_name("bggr", "x") == "BGGR" and mosaic_name(True, "x") == "RGGB" and mosaic_name(False, "x") is None


def test_a_one_channel_frame_without_its_mosaic_is_refused() -> None:
    rig = VirtualRig.from_preset("plane", ideal=True, **SIZES)
    ps = make_patterns("two-shot", rig.projector_size)
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    raw = np.zeros((240, 320), np.uint8)
    with pytest.raises(InputError, match="Bayer mosaic is not known"):
        FrameSetDecoder("two-shot", meta).decode([raw, raw])


def _scene(preset: str, bit_depth: int, **overrides):
    """A rig preset at this bit depth: (rig, its calibration with the camera gamma, the two-shot pattern's meta,
    the pair as one colour per pixel)."""
    rig = VirtualRig.from_preset(preset, bit_depth=bit_depth, **SIZES, **overrides)
    cal = rig.calibration
    cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
    ps = make_patterns("two-shot", cal.projector_size)
    meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
    return rig, cal, meta, [rig.render(im) for im in ps.images]


@pytest.fixture(scope="module", params=[8, 12], ids=["8-bit", "12-bit"])
def face(request):
    """The face at this bit depth: a two-shot pair as one colour per pixel, its decoder inputs and truth."""
    return _scene("face", request.param)


def _decode(face, frames, mosaic, signs=True, edges=True):
    """(coverage, correct, within 1 mm) of the pair; signs=False: without the lacking channel's signs from the
    G edges (app/decode/fast/lacking.py), edges=False: without its edges from the G edges (lacking_edges.py)."""
    rig, cal, meta, _ = face
    gt = rig.ground_truth
    dec = FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm, mosaic=mosaic)
    dec.decoder.signs_taken = not signs
    if not edges:
        p = dec.decoder.params
        dec.decoder.params = replace(p, label=replace(p.label, mosaic_edges=False))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EmptyResultWarning)
        res = dec.decode(frames)
    cov, cor, _, _ = score(res.stripes.column, res.depth, gt.column, gt.depth, gt.lit)
    return cov, cor, within_1mm(res.depth, gt.depth)


@pytest.mark.parametrize("mosaic", MOSAICS)
def test_raw_mosaic_depth_against_ground_truth(face, mosaic) -> None:
    frames = face[3]
    full, _, _ = _decode(face, frames, None)
    raw = [sample_mosaic(f, mosaic) for f in frames]
    assert raw[0].ndim == 2
    cov, cor, w1 = _decode(face, raw, mosaic)
    # (320x240: the 3-CCD camera covers 94 % of the face, RGGB raw 88-90 %, OpenCV's demosaic ~78 %)
    assert cov > 0.83 and cov > full - 0.11
    assert cor > 0.99 and w1 > 0.75
    code = getattr(cv2, f"COLOR_Bayer{mosaic}2RGB")
    demosaiced, _, _ = _decode(face, [cv2.cvtColor(r, code) for r in raw], None)
    assert cov > demosaiced + 0.04  # the reconstruction along the stripes beats a photographic demosaic
    # decoded with the wrong order, the same frames give much less
    wrong = {"RGGB": "BGGR", "BGGR": "RGGB", "GRBG": "GBRG", "GBRG": "GRBG"}[mosaic]
    assert _decode(face, raw, wrong)[0] < cov - 0.2


@pytest.mark.parametrize("mosaic", MOSAICS)
def test_the_g_edges_give_the_lacking_channels_aliased_signs(face, mosaic) -> None:
    raw = [sample_mosaic(f, mosaic) for f in face[3]]
    cov, cor, w1 = _decode(face, raw, mosaic)
    # the same reconstruction without the signs from the G edges
    cov0, cor0, w10 = _decode(face, raw, mosaic, signs=False)
    # (320x240: 88.3-90.3 % with them, 86.0-87.5 % without, for every order and both depths)
    assert cov > cov0 + 0.015 and cor > 0.99 and cor >= cor0 - 0.001 and w1 >= w10 - 0.002


@pytest.mark.parametrize("mosaic", MOSAICS)
def test_the_g_edges_place_the_lacking_channels_edges(face, mosaic) -> None:
    raw = [sample_mosaic(f, mosaic) for f in face[3]]
    cov, cor, w1 = _decode(face, raw, mosaic)
    cov0, _, w10 = _decode(face, raw, mosaic, edges=False)
    # (320x240: within 1 mm 85.9-86.7 % with them, 79.3-82.0 % without, coverage within 0.1 point, for every
    # order and both depths)
    assert w1 > w10 + 0.03 and cov > cov0 - 0.002 and cor > 0.99


def test_a_mirrored_rig_gets_the_lacking_channels_edges_too() -> None:
    face = _scene("face", 8, projector_roll_deg=180.4)  # columns fall as x grows: decoded mirrored
    raw = [sample_mosaic(f, "RGGB") for f in face[3]]
    dec = FrameSetDecoder("two-shot", face[2], face[1], face[0].depth_range_mm, mosaic="RGGB")
    assert dec.decoder.mirrored
    cov, cor, w1 = _decode(face, raw, "RGGB")
    cov0, _, w10 = _decode(face, raw, "RGGB", edges=False)
    # (320x240: within 1 mm 87.8 % with them, 83.2 % without)
    assert w1 > w10 + 0.03 and cov > cov0 - 0.002 and cor > 0.98


def test_lacking_edges_interpolate_the_g_edges_and_move_the_ends_by_their_pull() -> None:
    # a chain of 2-pixel stripes: codes flip B (bit 1) except at two G edges (bit 0); the true edges are
    # 10.3 + 2 q, each B edge measured 0.25 px towards the column lacking B (columns of parity 0 hold B here)
    codes = np.array([0, 2, 0, 1, 3, 1, 3, 2, 0, 2, 0], np.int8)  # edges: B B G B B B G B B B
    truth = 10.3 + 2.0 * np.arange(len(codes) - 1)
    is_b = (codes[:-1] ^ codes[1:]) == 2
    lacking_left = (np.floor(truth).astype(int) % 2) != 0  # the column left of the edge lacks B (B in even ones)
    measured = truth - np.where(is_b, np.where(lacking_left, 0.25, -0.25), 0.0)
    nx = measured.copy()
    lacking_edges(nx, len(nx), codes, 2, 1)
    np.testing.assert_allclose(nx[2:7], truth[2:7], atol=1e-12)  # between the G edges: interpolated
    np.testing.assert_allclose(nx, truth, atol=1e-12)  # beyond them: moved by the pull the others showed
    wide = 10.3 + 3.0 * np.arange(len(codes) - 1)  # 3-pixel stripes: B resolves its own edges; left as they are
    nx = wide - np.where(is_b, 0.25, 0.0)
    want = nx.copy()
    lacking_edges(nx, len(nx), codes, 2, 1)
    np.testing.assert_array_equal(nx, want)


def test_lacking_edges_beyond_the_outer_g_edges_follow_the_g_edges_stripe_step() -> None:
    # stripes widening from 1.8 px by 0.01 px a stripe (a surface turning towards the camera); G edges measured
    # exactly, every B edge off by up to 0.8 px (aliased, as where a chain meets the image's edge)
    codes = np.array([0, 2, 0, 1, 3, 1, 3, 2, 0, 2, 0, 1, 3, 1, 3, 1, 0, 2, 0], np.int8)
    q = np.arange(len(codes) - 1)
    truth = 40.2 + 1.8 * q + 0.005 * q * q
    is_b = (codes[:-1] ^ codes[1:]) == 2
    g_edges = np.flatnonzero(~is_b)
    assert len(g_edges) >= 3 and g_edges[0] > 0 and g_edges[-1] < len(q) - 1  # B edges beyond both outer ones
    noise = np.random.default_rng(3).uniform(-0.8, 0.8, len(q))
    nx = truth + np.where(is_b, noise, 0.0)
    lacking_edges(nx, len(nx), codes, 2, 1)
    # between G edges the interpolation's error is the curvature's (< 0.05 px here); beyond them the line of
    # the G edges' mean step, off by the widening over the stripes it carries on (< 0.2 px), not by the noise
    inner = slice(g_edges[0], g_edges[-1] + 1)
    assert np.abs(nx[inner] - truth[inner]).max() < 0.05
    assert np.abs(nx - truth).max() < 0.2 and np.abs(noise[is_b]).max() > 0.6


@pytest.mark.parametrize("segmentation", ["runs", "both"])
@pytest.mark.parametrize("mosaic", MOSAICS)
def test_the_fused_signs_give_the_maps_of_the_separate_pass(face, mosaic, segmentation) -> None:
    """The decoder flips the lacking channel's differences in its row loop (fast/lacking.py); the specification
    is the separate pass that swaps the frames' values first (mosaic_signs.lacking_signs), then decodes the
    swapped frames without the signs: the same columns and depths bit for bit."""
    rig, cal, meta, frames = face
    raw = [sample_mosaic(f, mosaic) for f in frames]
    fused = FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm, segmentation, mosaic=mosaic)
    separate = FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm, segmentation, mosaic=mosaic)
    separate.decoder.signs_taken = True
    rgb = fused.rgb(raw)
    swapped = lacking_signs(rgb[0], rgb[1], mosaic, separate.decoder)
    assert (swapped[0] != rgb[0]).sum() > 500  # (the pass changes the lacking channel at many pixels)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EmptyResultWarning)
        col, depth = fused.stripes_and_depth(raw)
        want_col, want_depth = separate.stripes_and_depth(list(swapped))
        plain_col, _ = separate.stripes_and_depth(rgb)
    assert not np.array_equal(plain_col.column.view(np.uint32), want_col.column.view(np.uint32))
    assert np.array_equal(col.column.view(np.uint32), want_col.column.view(np.uint32))
    assert np.array_equal(depth.view(np.uint32), want_depth.view(np.uint32))
    assert np.isfinite(col.column).mean() > 0.5


@pytest.fixture(scope="module", params=[8, 12], ids=["8-bit", "12-bit"])
def panel(request):
    """The colour panel at this bit depth (saturated colours: much crosstalk relative to a channel's signal)."""
    return _scene("colour_panel", request.param)


@pytest.mark.parametrize("mosaic", MOSAICS)
def test_the_leak_consistent_fill_gains_on_saturated_colours(panel, mosaic) -> None:
    rig, cal, meta, frames = panel
    gt = rig.ground_truth
    raw = [sample_mosaic(f, mosaic) for f in frames]
    found = {}
    for leaks in ("calibration", NO_LEAKS):
        dec = FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm, mosaic=mosaic)
        if leaks == "calibration":
            assert dec.leaks == mosaic_leaks(cal.color_mixing) != NO_LEAKS
        else:
            dec.leaks = leaks
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EmptyResultWarning)
            res = dec.decode(raw)
        found[leaks] = score(res.stripes.column, res.depth, gt.column, gt.depth, gt.lit)[:2]
    (cov, cor), (cov0, _) = found["calibration"], found[NO_LEAKS]
    # (320x240: 86.7-88.0 % with the leaks, 85.8-87.3 % without, for every order and both depths; 72-74 % without
    # before the sign model's pixels kept its sign through the unmixing, lacking_fill.py, which recovers most of it)
    assert cov > 0.77 and cov > cov0 + 0.003 and cor > 0.99


def test_the_sign_models_median_is_the_median_of_any_window() -> None:
    """fast/lacking.py takes the local stripe width as the median of up to 13 runs by a sorting network: for
    every window size and many windows (with ties, as runs of equal lengths give), numpy's median exactly."""
    from app.decode.fast.median13 import median13

    rng = np.random.default_rng(7)
    for trial in range(400):
        v = rng.integers(1, 6, 40) / rng.integers(1, 4, 40) if trial % 2 else rng.random(40) * 3
        lo = int(rng.integers(0, 20))
        for m in range(1, 14):
            assert median13(v, lo, lo + m) == np.median(v[lo : lo + m]), (trial, lo, m)


def _without_leak_removal(monkeypatch) -> None:
    """Decoders made from now on unmix G with the reconstruction's lacking channel as it is (no lacking_leak.py)."""
    import app.decode.twoshot as twoshot
    from app.decode.fast.bundles import NO_LEAK

    monkeypatch.setattr(twoshot, "leak_channel", lambda *args: NO_LEAK)


@pytest.mark.parametrize("mosaic", MOSAICS)
def test_the_leak_into_g_at_the_stripes_amplitude_gains_on_saturated_colours(panel, mosaic, monkeypatch) -> None:
    raw = [sample_mosaic(f, mosaic) for f in panel[3]]
    cov, cor, w1 = _decode(panel, raw, mosaic)
    _without_leak_removal(monkeypatch)
    cov0, cor0, w10 = _decode(panel, raw, mosaic)
    # (320x240: 86.3-87.4 % with it, 84.8-85.9 % without, correct within 0.2 point, within 1 mm 0.3-0.6 point
    # lower on the pixels it adds, for every order and both depths)
    assert cov > cov0 + 0.008 and cor > 0.995 and cor >= cor0 - 0.003 and w1 > w10 - 0.01


def test_a_mirrored_rig_removes_the_leak_into_g_too(monkeypatch) -> None:
    panel = _scene("colour_panel", 8, projector_roll_deg=180.4)  # decoded mirrored: the columns' parity flips
    raw = [sample_mosaic(f, "RGGB") for f in panel[3]]
    cov, cor, _ = _decode(panel, raw, "RGGB")
    _without_leak_removal(monkeypatch)
    cov0, _, _ = _decode(panel, raw, "RGGB")
    # (320x240: 87.9 % with it, 86.6 % without)
    assert cov > cov0 + 0.007 and cor > 0.99


@pytest.mark.parametrize("mirrored", [0, 1])
@pytest.mark.parametrize("flipped", [False, True])
def test_the_leak_into_g_is_removed_at_the_neighbouring_columns_amplitude(mirrored, flipped) -> None:
    """lacking_leak.leak_row on one row of 16 pixels, B held by the odd columns as the camera saw them (by the
    even ones when mirrored): at each column lacking B, G changes by U[G, B] (sign(b) min(|b left|, |b right|) -
    b) where |b| is below that amplitude, b the camera's B difference (the other sign where the sign model
    flipped the pixel); nothing elsewhere, bit for bit in float32."""
    from app.decode.fast.bundles import NO_LACKING, Classifier, FrameTables
    from app.decode.fast.classify import classify_scratch
    from app.decode.fast.lacking_leak import leak_row
    from app.decode.response_inverse import response_inverse

    W = 16
    lin = np.tile(np.arange(256, dtype=np.float32) * np.float32(0.75), (3, 1))
    tables = FrameTables(lin, np.ones_like(lin), np.empty(0, np.int64), response_inverse(lin))
    unmix = np.array([[-0.07, 1.02, -0.1], [-0.01, -0.08, 1.01]], np.float32)
    leak = (0, 2, 1, mirrored)  # (G pattern channel 0, camera B, held by the odd columns)
    classifier = Classifier(unmix, np.float32(2), np.float32(0.03), np.float32(0.03), 8, NO_LACKING, leak)
    scratch = classify_scratch(2, W, 8)
    b_diff = np.array([5, 60, -7, -50, 0, 40, 30, 70, -90, -20, 10, 45, -44, -60, 3, 80])
    if mirrored:
        b_diff = np.roll(b_diff, -1)  # (the same neighbourhoods at the odd columns)
    f1 = np.full((1, W, 3), 100, np.uint8)
    f2 = f1.copy()
    f2[0, :, 2] = 100 + b_diff
    g = np.linspace(-3, 3, W).astype(np.float32)
    scratch.rows[0][:] = g
    scratch.rows[1][:] = 7.0
    n_flips = 0
    e = (b_diff * np.float32(0.75)).astype(np.float32)
    if flipped:  # (the sign model's pixels, with the camera differences lacking_row gave them)
        scratch.lacking.flips[:2] = (3, 5) if mirrored else (4, 6)
        n_flips = 2
        e[scratch.lacking.flips[:2]] *= -1
        scratch.lacking.flipped_c[:2] = e[scratch.lacking.flips[:2]]
    leak_row(f1, f2, 0, tables, classifier, scratch, n_flips)
    k = unmix[0, 2]
    want = g.copy()
    lacking = 0 if not mirrored else 1  # (W - 1 - 1 is even: mirrored, the odd columns lack B)
    for x in range(1, W - 1):
        if x % 2 != lacking:
            continue
        amplitude = min(abs(e[x - 1]), abs(e[x + 1]))
        if abs(e[x]) < amplitude:
            want[x] = want[x] + k * (np.float32(np.sign(e[x])) * amplitude - e[x])
    assert np.array_equal(scratch.rows[0], want)
    assert (want != g).sum() >= 3
    assert np.all(scratch.rows[1] == 7.0)  # (the B pattern channel keeps the reconstruction's values)


@pytest.mark.parametrize("mosaic", MOSAICS)
def test_a_gamma_cameras_lacking_channel_is_filled_in_linear_light(mosaic) -> None:
    """Vertical G stripes that leak into R and B, R and B straight in x (which the cubic keeps), in linear light,
    encoded by a camera of gamma 2.2: filled through the camera's response, the lacking channels' linear values are
    those of the scene to about a code; filled in the codes, several codes off beside the stripes."""
    from app.decode.colour import linearisation
    from app.decode.response_inverse import response_inverse

    gamma, kr, kb = 2.2, 0.09, 0.08
    x = np.arange(64)
    g = np.where((x // 2) % 2 == 0, 50.0, 230.0)
    scene = np.stack([200 - 2.0 * x + kr * g, g, 40 + 1.5 * x + kb * g], -1)[None].repeat(8, 0)
    frame = np.round(255 * (scene / 255) ** (1 / gamma)).astype(np.uint8)
    raw = sample_mosaic(frame, mosaic)
    lin = linearisation(256, gamma)[0]
    codes = site_codes(mosaic)
    for response, bound in ((response_inverse(lin), 1.5), (None, None)):
        rgb = stripe_rgb(raw, mosaic, leaks=(kr, kb), response=response)
        worst = []
        for c in (0, 2):
            lacking = ~np.isin(np.arange(64) % 2, [p for p in (0, 1) if c in codes[:, p]])
            inner = lacking & (x >= 3) & (x < 61)
            worst.append(np.abs(lin[c][rgb[:, inner, c]] - scene[:, inner, c]).max())
        if bound is not None:
            assert max(worst) < bound, worst
        else:
            assert min(worst) > 2.0, worst  # (the codes' fill: what the response's fill corrects)


def test_the_fill_in_linear_light_keeps_saturated_colours(panel, monkeypatch) -> None:
    from app.decode.response_inverse import identity_inverse

    raw = [sample_mosaic(f, "RGGB") for f in panel[3]]
    cov, cor, _ = _decode(panel, raw, "RGGB")
    monkeypatch.setattr(FrameSetDecoder, "response", lambda self, dtype: identity_inverse(dtype))
    cov0, cor0, _ = _decode(panel, raw, "RGGB")
    # (320x240: 86.7-86.9 % through the rig camera's gamma, 87.4-87.7 % in its codes at both depths; 82.1-82.9 % in
    # its codes before the sign model's pixels kept their sign through the unmixing, lacking_fill.py: the fill in
    # linear light now costs up to a point of coverage here, and is kept for its values, test above)
    assert cov > cov0 - 0.01 and cor > 0.995 and cor >= cor0 - 0.002


def test_a_flipped_fill_whose_unmixed_sign_the_leak_keeps_takes_the_models_sign() -> None:
    """lacking_fill.model_sign_codes: where exchanging the frames' B values leaves the unmixed B difference's sign
    (a small fill beside a strong G stripe, whose leak outweighs it), B's values move apart about their mean until
    the unmixed difference has the other sign at the magnitude the exchange left; elsewhere nothing changes."""
    from app.decode.fast.lacking_fill import model_sign_codes
    from app.decode.response_inverse import response_inverse

    lin = np.tile(np.arange(256, dtype=np.float32) * np.float32(0.75), (3, 1))
    response = response_inverse(lin)
    row = np.array([-0.01, -0.3, 1.01], np.float32)  # (the B pattern channel: camera G leaks into camera B)

    def unmixed(a, b):
        return float(sum(row[c] * (lin[c, b[c]] - lin[c, a[c]]) for c in range(3)))

    a, b = (50, 40, 101), (50, 200, 99)  # B exchanged: frame 2 - frame 1 is G +160 codes, B -2 (before: +2)
    before = unmixed((50, 40, 99), (50, 200, 101))
    exchanged = unmixed(a, b)
    assert before < 0 and exchanged < 0  # (the leak keeps the sign)
    na, nb = model_sign_codes(a, b, 2, row, response, before)
    moved = unmixed(na, nb)
    assert moved > 0 and abs(moved - abs(exchanged)) < 1.0  # (to within a code of B, 0.76 in linear units)
    assert na[:2] == a[:2] and nb[:2] == b[:2] and abs((na[2] + nb[2]) - (a[2] + b[2])) <= 1
    # the exchange already gave the other sign, before had no sign, or B does not enter the row: as given
    assert model_sign_codes(a, b, 2, row, response, -exchanged) == (a, b)
    assert model_sign_codes(a, b, 2, row, response, 0.0) == (a, b)
    no_b = np.array([-0.01, -0.3, 0.0], np.float32)
    assert model_sign_codes(a, b, 2, no_b, response, before) == (a, b)


def _coded_row(width: float, W: int = 160) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A row of the two-shot code's stripes, `width` camera pixels each: G's and B's differences (+-1 by each
    pixel's stripe) and B's true sign; B held by the odd columns, the even ones given B's wrong sign (as an
    aliased fill gives it)."""
    ps = make_patterns("two-shot", (512, 1))
    p1, p2 = ps.images[0][0].astype(int), ps.images[1][0].astype(int)
    stripe = ((np.arange(W) + 0.5) / width).astype(int) + 40  # (from the 40th stripe: an arbitrary place in the code)
    g = np.sign(p2[stripe, 1] - p1[stripe, 1]).astype(np.float32)
    b = np.sign(p2[stripe, 2] - p1[stripe, 2]).astype(np.float32)
    c = np.where(np.arange(W) % 2 == 1, b, -b).astype(np.float32)
    return g, c, b


def _g_runs(g: np.ndarray) -> list[tuple[int, int]]:
    """The pixel ranges (first, last) of G's runs of one sign between two G edges."""
    edges = np.flatnonzero(g[1:] != g[:-1]) + 1
    return [(a, b - 1) for a, b in itertools.pairwise(edges)]


@pytest.mark.parametrize(("width", "carried"), [(2.0, True), (2.6, False)])
def test_a_refused_run_takes_its_neighbours_phase_across_the_g_edge(width, carried) -> None:
    """The lacking channel is constant across a G edge (the code flips one channel at a stripe edge): a run whose
    B columns dissent takes the phase of the runs beside it where the stripes sit at B's Nyquist limit (~2 camera
    pixels), and keeps none where they are wide enough for its own columns."""
    from app.decode.fast.lacking import lacking_flips, lacking_scratch

    g, c, b = _coded_row(width)
    W = g.size
    runs = [r for r in _g_runs(g) if 20 < r[0] and r[1] < W - 20 and r[1] - r[0] >= 7]  # four or more B columns
    first, last = runs[len(runs) // 2]
    held = [x for x in range(first, last + 1) if x % 2 == 1]
    c[held[1]] *= -1  # two of its B columns dissent (inside it: its neighbours' columns agree)
    c[held[2]] *= -1
    s = lacking_scratch(W)
    n = lacking_flips(g, c, np.zeros_like(g), 1, s)  # (no noise)
    flipped = set(s.flips[:n].tolist())
    lacking = [x for x in range(first, last + 1) if x % 2 == 0]
    # the other runs' lacking columns come back to B's true sign (each had the wrong one): all of them but a
    # few at 2.6 pixels a stripe, where a column near a B edge may sit in the other stripe of the model's
    others = [x for f, t in _g_runs(g) if (f, t) != (first, last) and 20 < f and t < W - 20 for x in range(f, t + 1)]
    others = [x for x in others if x % 2 == 0]
    assert np.mean([x in flipped for x in others]) > 0.9
    if carried:
        assert all(x in flipped for x in lacking)
        assert all(np.sign(-c[x]) == b[x] for x in lacking)  # (flipping the wrong sign gives the true one)
    else:
        assert not any(x in flipped for x in lacking)
