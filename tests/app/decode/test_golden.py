"""The fast decoders reproduce their committed golden maps bit for bit (golden/make_golden.py).

The goldens hold the frames, calibration and settings of each case, so only a change of the decoder (or of
the triangulation) can move them; such a change rewrites the goldens in a reviewed commit.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from golden.make_golden import CASES, calibration_from, decode_case, unpack_bits

GOLDEN = Path(__file__).parent / "golden" / "golden_320x240.npz"


@pytest.fixture(scope="module")
def golden():
    with np.load(GOLDEN) as data:
        yield {k: data[k] for k in data.files}


def _differences(got: np.ndarray, want: np.ndarray) -> str:
    bad = got.view(np.uint32) != want.view(np.uint32)
    ys, xs = np.nonzero(bad)
    return f"{bad.sum()} pixels differ, first at (x={xs[0]}, y={ys[0]}): {got[ys[0], xs[0]]} vs {want[ys[0], xs[0]]}"


def test_every_case_is_in_the_goldens(golden):
    assert {k.split("/")[0] for k in golden if k.endswith("/settings")} == set(CASES)


@pytest.mark.parametrize("name", list(CASES))
def test_decoder_output_is_bit_identical_to_the_golden(golden, name):
    info = json.loads(str(golden[f"{name}/settings"]))
    src = info["frames"]
    frames = [golden[f"{src}/frame{i}"] for i in range(len(info["meta"]["images"]))]
    cal = calibration_from(golden, src)
    column, depth = decode_case(info["scheme"], frames, cal, info, info["segmentation"])
    shape = tuple(info["shape"])
    want = unpack_bits(golden[f"{name}/column"], shape)
    assert np.isfinite(want).mean() > 0.5  # a golden that decodes nothing would prove nothing
    assert np.array_equal(column.view(np.uint32), want.view(np.uint32)), _differences(column, want)
    if f"{name}/depth" in golden:
        want_depth = unpack_bits(golden[f"{name}/depth"], shape)
        assert np.array_equal(depth.view(np.uint32), want_depth.view(np.uint32)), _differences(depth, want_depth)
