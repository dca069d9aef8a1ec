"""The gathered two-shot differences (app/decode/simd.py) against the scalar loop they replace: bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from synth import make_calibration, plane_depth, render

from app.decode import kernels
from app.decode.twoshot import TwoShotDecoder
from app.patterns import two_shot_patterns


@njit(cache=False)
def _dispatched(f1, f2, lin, dlin, unmix, ta, out):
    for y in range(f1.shape[0]):
        kernels._differences(f1, f2, y, lin, dlin, unmix, ta, out[y])


@njit(cache=False)
def _scalar(f1, f2, lin, dlin, u, ta, out):
    for y in range(f1.shape[0]):
        o = out[y]
        kernels._row_differences(
            f1[y], f2[y], lin[0], lin[1], lin[2], dlin[0], dlin[1], dlin[2],
            u[0, 0], u[0, 1], u[0, 2], u[1, 0], u[1, 1], u[1, 2], ta, o[0], o[1], o[2], o[3],
        )  # fmt: skip


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("width", [5, 16, 17, 47, 640])
def test_gathered_differences_equal_the_scalar_loop(dtype, width):
    rng = np.random.default_rng(width)
    levels = np.iinfo(dtype).max + 1
    f1 = rng.integers(0, levels, (3, width, 3)).astype(dtype)
    f2 = rng.integers(0, levels, (3, width, 3)).astype(dtype)
    f1[0, :4] = 0  # both ends of the tables
    f2[0, :4] = levels - 1
    lin = (255 * rng.random((3, levels))).astype(np.float32)
    dlin = rng.random((3, levels)).astype(np.float32)
    unmix = rng.normal(size=(2, 3)).astype(np.float32)
    ta = np.float32(1.0)
    got = np.full((3, 6, width), np.nan, np.float32)
    want = np.full((3, 6, width), np.nan, np.float32)
    _dispatched(f1, f2, lin, dlin, unmix, ta, got)
    _scalar(f1, f2, lin, dlin, unmix, ta, want)
    np.testing.assert_array_equal(got[:, :4], want[:, :4])
    assert np.isnan(got[:, 4:]).all()  # rows past the fourth are left alone


def test_frames_that_are_views_decode_as_their_copies():
    """Non-contiguous frames (the scalar loop's specialisation) give the contiguous frames' (gathers') result."""
    cal = make_calibration()
    ps = two_shot_patterns(cal.projector_size)
    z, ray = plane_depth(cal, 800.0, slope_x=0.3)
    f1, _ = render(cal, ps.images[0], z, ray, seed=1, ambient=0.1)
    f2, _ = render(cal, ps.images[1], z, ray, seed=2, ambient=0.1)
    dec = TwoShotDecoder(ps.params, cal.projector_size[0])
    pad1 = np.zeros((f1.shape[0], f1.shape[1] + 3, 3), f1.dtype)
    pad2 = np.zeros_like(pad1)
    pad1[:, 3:] = f1
    pad2[:, 3:] = f2
    view1, view2 = pad1[:, 3:], pad2[:, 3:]
    assert not view1.flags.c_contiguous
    a = dec.decode(f1, f2)
    b = dec.decode(view1, view2)
    assert np.isfinite(a.column).mean() > 0.5
    np.testing.assert_array_equal(a.column, b.column)
