"""The camera response's inverse (app/decode/response_inverse.py): each code's linear value back to the code."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from app.decode.colour import linearisation
from app.decode.response_inverse import identity_inverse, nearest_code, response_inverse


@njit(cache=False)
def _codes_of(values, c, inverse):
    codes, scale, root = inverse.codes, inverse.scale, inverse.root
    steps = codes.shape[0] // 3
    top = inverse.lin.shape[1] - 1
    out = np.empty(values.shape[0], np.int64)
    for i in range(values.shape[0]):
        out[i] = np.int64(nearest_code(values[i], c * steps, codes, scale, root, np.float32(steps - 2), top))
    return out


@pytest.mark.parametrize(("levels", "gamma"), [(256, 1.8), (256, 2.2), (256, 1.0), (65536, 1.8), (65536, 1.0)])
def test_every_codes_linear_value_comes_back_to_the_code(levels, gamma) -> None:
    lin = linearisation(levels, gamma)[0]
    inverse = response_inverse(lin)
    assert inverse.root == (gamma != 1.0)
    for c in range(3):
        assert np.array_equal(_codes_of(lin[c], c, inverse), np.arange(levels))


def test_values_between_codes_go_to_the_nearer_one() -> None:
    lin = linearisation(256, 2.2)[0]
    inverse = response_inverse(lin)
    v = np.arange(40, 250)
    third = lin[2, v] + (lin[2, v + 1] - lin[2, v]) / 3  # (a third of the way to the next code)
    assert np.array_equal(_codes_of(third.astype(np.float32), 2, inverse), v)
    assert np.array_equal(
        _codes_of((lin[2, v + 1] - 1e-3 * (lin[2, v + 1] - lin[2, v])).astype(np.float32), 2, inverse), v + 1
    )
    # below the first and beyond the last code: clamped
    assert list(_codes_of(np.array([-5.0, 1e6], np.float32), 2, inverse)) == [0, 255]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_a_linear_cameras_inverse_rounds_half_up_exactly(dtype) -> None:
    inverse = identity_inverse(dtype)
    top = np.iinfo(dtype).max
    assert not inverse.root
    v = (np.arange(0, min(top, 4000) * 16) / 16.0).astype(np.float32)  # (the fill's sixteenths: ties included)
    assert np.array_equal(_codes_of(v, 1, inverse), np.floor(v + 0.5).astype(np.int64))
    assert _codes_of(np.array([top + 0.4], np.float32), 0, inverse)[0] == top


def test_a_decreasing_response_is_refused() -> None:
    lin = linearisation(256, 1.8)[0].copy()
    lin[1, 10] = lin[1, 9] - 1
    with pytest.raises(ValueError, match="increasing"):
        response_inverse(lin)
