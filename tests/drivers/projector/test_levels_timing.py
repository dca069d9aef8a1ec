"""Pure parts of the projector driver: the output-levels table and the flip statistics."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from drivers.projector.levels import apply_levels, levels_lut
from drivers.projector.timing import flip_stats


def test_identity_levels_leave_every_value_unchanged():
    np.testing.assert_array_equal(levels_lut(), np.arange(256))
    np.testing.assert_array_equal(levels_lut(1, 1.0), np.arange(256))
    img = np.random.default_rng(1).integers(0, 256, (4, 5, 3), dtype=np.uint8)
    np.testing.assert_array_equal(apply_levels(img, levels_lut()), img)


def test_gamma_and_brightness_values():
    lut = levels_lut(gamma=2.0, brightness=0.5)
    assert lut[0] == 0 and lut[255] == 128  # round(127.5) -> 128 (half to even is 128)
    assert lut[64] == round(127.5 * (64 / 255) ** 0.5)
    assert (np.diff(lut.astype(int)) >= 0).all()
    assert not levels_lut(brightness=0).any()
    lifted = levels_lut(gamma=2.2)
    assert lifted[128] > 128 and lifted[255] == 255  # gamma > 1 lifts mid-tones, keeps white


@pytest.mark.parametrize("kw", [{"gamma": 0}, {"gamma": -1}, {"gamma": "2"}, {"brightness": 1.5}, {"brightness": -0.1}])
def test_bad_levels_are_input_errors(kw):
    with pytest.raises(InputError, match=r"projector (gamma|brightness)"):
        levels_lut(**kw)


def test_flip_stats_of_known_times():
    ms = 1_000_000
    times = [0, 16 * ms, 33 * ms, 50 * ms, 100 * ms]  # intervals 16, 17, 17, 50 ms
    s = flip_stats(times, target_hz=60)
    assert s.flips == 5
    assert s.mean_ms == pytest.approx(25.0)
    assert s.jitter_ms == pytest.approx(np.std([16, 17, 17, 50]))
    assert (s.min_ms, s.max_ms, s.late) == (16.0, 50.0, 1)
    assert "5 flips, interval 25.000 ms mean (40.00 Hz)" in s.summary()
    assert flip_stats(times).late == 0
    assert flip_stats([7]).flips == 1 and "too few" in flip_stats([7]).summary()
