"""The public API on the other kinds of dump a rig records: white-light texture frames colour each scan with the
object's own colour, and a single-chip camera's raw Bayer frames decode against the virtual rig's ground truth."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import slscan
from core.dump import read_dump as read_index
from core.imageio import read_float_tiff

ROOT = Path(__file__).resolve().parents[2]


def _render(out: Path, scene: str, size: str, *extra: str) -> Path:
    cmd = [sys.executable, "-m", "app.cli", "sim", "render", "--scene", scene, "--scheme", "two-shot"]
    cmd += ["--camera-size", size, "--out", str(out), *extra]
    subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT, timeout=120)
    return out


@pytest.fixture(scope="module")
def texture_dump(tmp_path_factory) -> Path:
    """The cube (saturated stickers), 3 cycles with a texture frame after every 2 pattern frames."""
    return _render(
        tmp_path_factory.mktemp("api-tex") / "cube", "cube", "320x240", "--cycles", "3", "--texture-every", "2"
    )


@pytest.fixture(scope="module")
def bayer_dump(tmp_path_factory) -> Path:
    """The plane filmed by an RGGB single-chip camera: raw one-channel frames, the mosaic named in dump.yaml; at
    640x480, where a stripe is two camera pixels wide (a mosaic's colour sites are two apart)."""
    out = tmp_path_factory.mktemp("api-bayer") / "plane"
    return _render(out, "plane", "640x480", "--cycles", "2", "--set", "bayer=RGGB")


def test_texture_frames_are_never_paired_and_colour_the_nearest_later_sets(texture_dump):
    dump = slscan.read_dump(texture_dump)
    index = read_index(texture_dump)
    textures = index.texture_indices()
    assert len(textures) >= 2
    texture_ids = {index.frames[i].frame_id for i in textures}
    sets = dump.frame_sets()
    assert len(sets) > 0
    decoder = slscan.Decoder.for_dump(dump)
    for frames in sets:
        assert not texture_ids & set(frames.frame_ids)  # a white frame has no stripe code
        first_id = min(frames.frame_ids)
        earlier = [index.frames[i] for i in textures if index.frames[i].frame_id < first_id]
        if not earlier:
            assert frames.texture is None
            continue
        nearest = index.load_frame(index.frames.index(earlier[-1]))
        np.testing.assert_array_equal(frames.texture, nearest)
        scan = decoder.decode(frames)
        assert scan.valid.mean() > 0.2
        np.testing.assert_array_equal(scan.colors, nearest[scan.valid])  # the object's colour, not the stripes'
        # a plain list of the same frames is coloured by the pair's mean instead: red is never lit by the pair
        plain = decoder.decode(list(frames))
        assert plain.colors[:, 0].mean() < 0.5 * scan.colors[:, 0].mean()


def test_raw_bayer_frames_decode_against_the_ground_truth(bayer_dump):
    dump = slscan.read_dump(bayer_dump)
    assert dump.mosaic == "RGGB"
    decoder = slscan.Decoder.for_dump(dump)
    assert decoder.mosaic == "RGGB"
    truth = read_float_tiff(bayer_dump / "ground_truth" / "depth.tiff")
    sets = dump.frame_sets()
    assert len(sets) == 3
    for frames in sets:
        assert all(f.shape == (480, 640) for f in frames)  # one channel, as the sensor gave it
        scan = decoder.decode(frames)
        assert scan.valid.mean() > 0.85, scan.valid.mean()
        err = np.abs(scan.depth - truth)[scan.valid & (truth > 0)]
        assert np.median(err) < 0.5 and np.mean(err < 2.0) > 0.99, (np.median(err), np.mean(err < 2.0))
        assert scan.colors.shape == (int(scan.valid.sum()), 3)


def test_a_raw_frame_without_its_mosaic_is_one_line(bayer_dump):
    dump = slscan.read_dump(bayer_dump)
    frames = list(dump.frame_sets()[0])
    decoder = slscan.Decoder(dump.patterns, dump.calibration, dump.depth_range_mm)  # mosaic not given
    with pytest.raises(slscan.InputError, match=r"frames\[0\] is a grey image \(640x480\).*mosaic") as err:
        decoder.decode(frames)
    assert "\n" not in str(err.value)
    with pytest.raises(slscan.InputError, match="mosaic"):
        slscan.Decoder(dump.patterns, dump.calibration, dump.depth_range_mm, mosaic="RGBG")
