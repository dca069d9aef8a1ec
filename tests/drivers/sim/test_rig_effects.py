"""Each optical / sensor effect of the virtual rig changes the image the way it should."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from drivers.sim.rig import VirtualRig
from drivers.sim.scene import parse_scene

SMALL = (160, 120)  # same field of view as 640x480 (focal length scales with width), 16x faster


def flat(level: int | tuple[int, int, int], size: tuple[int, int] = (1024, 768)) -> np.ndarray:
    return np.broadcast_to(np.asarray(level, np.uint8), (size[1], size[0], 3)).copy()


def rig(**kw) -> VirtualRig:
    return VirtualRig.from_preset("plane", ideal=True, camera_size=SMALL, **kw)


def test_ambient_adds_its_colour_and_cancels_in_a_two_shot_difference() -> None:
    dark = rig(ambient=0.2)
    img = dark.render(flat(0)).reshape(-1, 3)
    expected = np.round(255 * 0.2 * np.array(dark.options.ambient_color))
    assert np.all(np.abs(img - expected) <= 1)
    assert img[:, 0].mean() > img[:, 1].mean() > img[:, 2].mean()  # warm room light
    clean = rig()
    a, b = flat((0, 150, 0)), flat((0, 0, 150))
    d_amb = dark.render(b).astype(int) - dark.render(a).astype(int)
    d_clean = clean.render(b).astype(int) - clean.render(a).astype(int)
    assert np.abs(d_amb - d_clean).max() <= 1  # the sign (and size) of frame2 - frame1 ignores ambient


def test_crosstalk_leaks_into_other_channels_as_the_true_colour_mixing_says() -> None:
    r = rig(crosstalk=0.1)
    M = r.calibration.color_mixing
    assert np.allclose(np.diag(M), 1) and 0.05 < M[0, 1] <= 0.1 and 0.05 < M[2, 1] <= 0.1
    img = r.render(flat((0, 200, 0))).reshape(-1, 3).astype(float)
    assert np.all(np.abs(img - 200 * M[:, 1]) <= 1)
    unmixed = img @ np.linalg.inv(M).T
    assert np.abs(unmixed[:, [0, 2]]).max() < 1.0 and np.abs(unmixed[:, 1] - 200).max() < 1.0
    assert np.all(rig().render(flat((0, 200, 0)))[..., [0, 2]] == 0)  # without crosstalk: no leak


def test_clipping_at_the_top() -> None:
    r = rig(exposure=3.0)
    assert np.all(r.render(flat(128)) == 255)
    assert np.all(np.abs(r.render(flat(50)).astype(int) - 150) <= 1)
    assert r.render(flat(50)).max() < 255


def test_noise_has_the_predicted_size_and_is_deterministic_per_seed() -> None:
    r = rig(noise=True, seed=1)
    frames = np.stack([r.render(flat(128)) for _ in range(24)]).astype(float)
    x = 128 / 255
    sigma = np.sqrt(r.options.read_noise**2 + x / r.options.full_well) * 255
    measured = frames.std(axis=0, ddof=1).mean()
    assert abs(measured - sigma) < 0.15 * sigma
    assert abs(frames.mean() - 128) < 0.2
    assert not np.array_equal(frames[0], frames[1])  # fresh noise every call
    again = rig(noise=True, seed=1)
    assert np.array_equal(again.render(flat(128)), frames[0].astype(np.uint8))
    other = rig(noise=True, seed=2)
    assert not np.array_equal(other.render(flat(128)), frames[0].astype(np.uint8))


def test_gamma_and_black_level() -> None:
    assert abs(int(rig(camera_gamma=2.2).render(flat(64))[5, 5, 1]) - 136) <= 1  # 255 (64/255)^(1/2.2)
    assert abs(int(rig(projector_gamma=2.2).render(flat(128))[5, 5, 1]) - 55) <= 1  # 255 (128/255)^2.2
    assert abs(int(rig(black_level=0.05).render(flat(0))[5, 5, 1]) - 13) <= 1  # light leak


# psf_sigma_px is given at 640 px width (1 camera px here); defocus in projector px (~0.5 camera px each)
@pytest.mark.parametrize("effect", [{"psf_sigma_px": 4.0}, {"defocus_sigma_px": 3.0}])
def test_blur_spreads_a_narrow_projector_stripe_and_keeps_its_energy(effect: dict) -> None:
    sharp, blurred = rig(), rig(**effect)
    pat = flat(0)
    pat[:, 498:502, 1] = 255
    a = sharp.render(pat)[..., 1].astype(float)
    b = blurred.render(pat)[..., 1].astype(float)
    assert (b > 2).sum(axis=1).mean() > (a > 2).sum(axis=1).mean() + 1
    assert b.max() < a.max()
    assert abs(b.sum() - a.sum()) < 0.05 * a.sum()


def test_shading_and_projector_shadows() -> None:
    tilted = VirtualRig.from_preset("plane_tilted", camera_size=SMALL, ideal=True, shading=True)
    img = tilted.render(flat(200))[..., 1].astype(float)
    assert img[:, :20].mean() != pytest.approx(img[:, -20:].mean(), abs=3)  # incidence and distance vary
    steps = VirtualRig.from_preset("steps", camera_size=SMALL, ideal=True, ambient=0.1)
    gt = steps.ground_truth
    shadow = gt.visible & ~gt.lit
    assert shadow.mean() > 0.02  # the near step shadows what is behind it
    white = steps.render(flat(255))[..., 1]
    assert white[shadow].max() < white[gt.lit].min()  # only ambient light in the shadow


def test_motion_moves_objects_between_frames_and_ground_truth_follows() -> None:
    data = {
        "description": "a moving ball",
        "depth_range_mm": [600, 900],
        "objects": [{"type": "sphere", "center": [0, 0, 700], "radius": 40, "moves": True}],
    }
    scene = parse_scene(data, Path("ball.yaml"))
    r = VirtualRig.from_scene(scene, ideal=True, camera_size=SMALL, motion_mm_per_frame=[0, 0, 5])
    nearest = []
    for _ in range(3):
        r.render(flat(255))
        d = r.ground_truth.depth
        nearest.append(d[d > 0].min())
    assert np.allclose(np.diff(nearest), 5.0, atol=0.05)


def test_true_response_helpers_predict_a_flat_level_on_the_white_plane() -> None:
    r = rig(projector_gamma=2.2, camera_gamma=1.8, black_level=0.03, exposure=0.8)
    for level in (0, 40, 128, 255):
        expected = r.camera_response(0.8 * r.projector_light(level))
        assert abs(float(r.render(flat(level))[5, 5, 1]) - expected) <= 0.5


def test_specular_lobe_adds_a_highlight_only_where_it_should() -> None:
    glossy = VirtualRig.from_preset("cylinder", camera_size=SMALL, ideal=True, shading=True, specular=True)
    matte = VirtualRig.from_preset("cylinder", camera_size=SMALL, ideal=True, shading=True)
    a = glossy.render(flat(128)).astype(int).sum(axis=2)
    b = matte.render(flat(128)).astype(int).sum(axis=2)
    assert np.all(a >= b)  # a lobe only ever adds light
    gain = a - b
    assert gain.max() > 60  # a bright band on the glossy cylinder
    assert (gain > 10).mean() < 0.3  # ... and not everywhere
    assert np.all(gain[~glossy.ground_truth.lit] == 0)  # no highlight in projector shadow


def test_bayer_sensor_records_one_channel_per_site_in_its_mosaic() -> None:
    from core.mosaic import MOSAICS, sample_mosaic

    plain = rig().render(flat((200, 100, 30)))
    for order in MOSAICS:
        raw = rig(bayer=order).render(flat((200, 100, 30)))
        assert raw.shape == plain.shape[:2] and raw.dtype == plain.dtype
        assert np.array_equal(raw, sample_mosaic(plain, order))
        h, w = raw.shape
        assert raw[h // 2 & ~1, w // 2 & ~1] == {"R": 200, "G": 100, "B": 30}[order[0]]
    assert rig(bayer=True).mosaic == "RGGB"  # the former `bayer: true`
    assert rig(bayer=False).mosaic is None


def test_bayer_option_names_its_field() -> None:
    with pytest.raises(InputError, match=r"option 'bayer'.*RGBG.*not a Bayer mosaic"):
        rig(bayer="RGBG")


def test_twelve_bit_frames_fill_sixteen_bits() -> None:
    img = rig(bit_depth=12).render(flat((200, 100, 30)))
    assert img.dtype == np.uint16 and np.all(img % 16 == 0) and img.max() > 4095
