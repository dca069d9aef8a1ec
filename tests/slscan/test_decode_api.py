"""The public API decodes a rendered dump to the virtual rig's ground truth; bad frames get one line."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

import slscan
from app.decode.pipeline import DepthRangeWarning, EmptyResultWarning
from core.imageio import read_float_tiff


@pytest.fixture(scope="module")
def dump(plane_dump):
    return slscan.read_dump(plane_dump)


@pytest.fixture(scope="module")
def decoder(dump):
    return slscan.Decoder.for_dump(dump)


@pytest.fixture(scope="module")
def truth(plane_dump):
    return read_float_tiff(plane_dump / "ground_truth" / "depth.tiff")


def test_a_dump_gives_its_frame_sets_patterns_and_calibration(dump):
    assert dump.scheme == "two-shot" and len(dump) == 4
    assert dump.calibration.camera_size == (320, 240) and dump.patterns.size == (1024, 768)
    assert dump.depth_range_mm == (600.0, 900.0)
    sets = dump.frame_sets()
    assert len(sets) == 3  # sliding pairs 1-2, 2-3, 3-4
    assert [s.frame_ids for s in sets] == [(1, 2), (3, 2), (3, 4)]  # pattern order: frames[p] saw pattern p
    assert [s.newest for s in sets] == [1, 0, 1]
    assert sets[0].previous is None and sets[1].previous is not None
    for s in sets:
        assert len(s) == 2 and all(f.shape == (240, 320, 3) and f.dtype == np.uint8 for f in s)
    assert sets[2].timestamp_ns > sets[1].timestamp_ns > sets[0].timestamp_ns
    assert len(dump.frame_sets(sliding=False)) == 2


def test_decoded_depth_matches_the_ground_truth(dump, decoder, truth):
    for frames in dump.frame_sets():
        scan = decoder.decode(frames)
        assert scan.depth.dtype == np.float32 and scan.depth.shape == (240, 320)
        assert scan.valid.dtype == bool and np.array_equal(scan.valid, scan.depth > 0)
        assert scan.valid.mean() > 0.9  # the plane fills the view
        err = np.abs(scan.depth - truth)[scan.valid & (truth > 0)]
        assert np.median(err) < 0.5 and np.mean(err < 2.0) > 0.99, (np.median(err), np.mean(err < 2.0))
        assert scan.frame_ids == frames.frame_ids and scan.timestamp_ns == frames.timestamp_ns


def test_points_colours_and_normals_of_a_scan(dump, decoder, truth):
    scan = decoder.decode(dump.frame_sets()[0])
    n = int(scan.valid.sum())
    assert scan.points.shape == (n, 3) and scan.points.dtype == np.float32
    assert scan.colors.shape == (n, 3) and scan.colors.dtype == np.uint8
    assert scan.normals.shape == (n, 3) and scan.normals.dtype == np.float32
    np.testing.assert_array_equal(scan.points[:, 2], scan.depth[scan.valid])
    # x = (u - cx) / fx * Z at a pixel, as the calibration's pinhole says (no camera distortion near the centre)
    K = dump.calibration.camera_matrix
    y, x = 120, 160
    i = int(np.flatnonzero(scan.valid.ravel()[: y * 320 + x + 1]).size - 1)
    assert scan.points[i, 0] == pytest.approx((x - K[0, 2]) / K[0, 0] * scan.depth[y, x], abs=0.05)
    # the plane is white under white light: the pair's mean is grey, red among them (stripes cancel)
    assert np.median(scan.colors, axis=0).min() > 60
    # normals: unit, facing the camera, and along the true plane's normal (fitted to its true points)
    good = np.isfinite(scan.normals).all(axis=1)
    assert good.mean() > 0.95
    assert np.allclose(np.linalg.norm(scan.normals[good], axis=1), 1.0, atol=1e-4)
    assert (np.sum(scan.normals[good] * scan.points[good], axis=1) < 0).all()
    truth_points = slscan.Scan(truth, truth, scan.image, decoder._decoder.triangulator.ray).points
    centred = truth_points - truth_points.mean(axis=0)
    plane_normal = np.linalg.svd(centred, full_matrices=False)[2][2]
    mean_normal = scan.normals[good].mean(axis=0)
    cos = abs(mean_normal @ plane_normal) / np.linalg.norm(mean_normal)
    assert np.degrees(np.arccos(min(1.0, cos))) < 1.0


def test_a_decoder_from_its_parts_decodes_the_same(dump, decoder, plane_dump):
    frames = dump.frame_sets()[2]
    from_files = slscan.Decoder(plane_dump / "patterns", plane_dump / "calibration.yaml", (600, 900))
    assert np.array_equal(from_files.decode(frames).depth, decoder.decode(frames).depth)
    # a plain list decodes as the pair it is (no motion handling without the frame before it): a still scene
    plain = decoder.decode(list(frames))
    assert plain.frame_ids == () and plain.timestamp_ns is None
    assert np.mean(plain.valid == decoder.decode(frames).valid) > 0.99


def test_bgr_frames_from_cv2_imread_are_named(dump, decoder, plane_dump):
    rec = [plane_dump / "frames" / f"{i:06d}.png" for i in (0, 1)]
    with pytest.raises(slscan.InputError) as err:
        decoder.decode([cv2.imread(str(p)) for p in rec])
    msg = str(err.value)
    assert "look BGR" in msg and "cv2.imread" in msg and "frame[..., ::-1]" in msg and "\n" not in msg
    # the same files converted decode
    assert decoder.decode([cv2.imread(str(p))[..., ::-1] for p in rec]).valid.mean() > 0.9


@pytest.mark.parametrize(
    ("make", "expect"),
    [
        (lambda f: [f[0].astype(np.float32), f[1]], r"frames\[0\] has dtype float32: expected uint8 or uint16"),
        (lambda f: [f[0][..., 1], f[1]], r"frames\[0\] is a grey image \(320x240\)"),
        (lambda f: [np.dstack([f[0], f[0][..., :1]]), f[1]], r"frames\[0\] has 4 channels"),
        (lambda f: [f[0][:200], f[1][:200]], r"frames\[0\] is 320x200 but the calibration's camera_size is 320x240"),
        (lambda f: [f[0]], r"frames: this scheme needs 2 frame\(s\) per set in pattern order, got 1"),
        (lambda f: f[0], r"frames: one image given"),
        (lambda f: [f[0], f[1].astype(np.uint16)], r"frames\[1\] is uint16 but frames\[0\] is uint8"),
        (lambda f: [f[0].tolist(), f[1]], r"frames\[0\] is a list, not a numpy array"),
    ],
)
def test_bad_frames_get_one_line(dump, decoder, make, expect):
    frames = list(dump.frame_sets()[0])
    with pytest.raises(slscan.InputError, match=expect) as err:
        decoder.decode(make(frames))
    assert "\n" not in str(err.value)


def test_a_depth_range_that_allows_every_copy_says_so(dump):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        decoder = slscan.Decoder(dump.patterns, dump.calibration)  # no range: (100, 5000)
        scan = decoder.decode(dump.frame_sets()[0])
    said = {w.category: str(w.message) for w in caught}
    assert not scan.valid.any()
    assert "depth range 100-5000 mm allows" in said[DepthRangeWarning] and "copies" in said[DepthRangeWarning]
    assert "copies" in said[EmptyResultWarning] and "dark" not in said[EmptyResultWarning]


def test_a_dump_without_calibration_and_a_missing_dump_are_input_errors(tmp_path, plane_dump):
    with pytest.raises(slscan.InputError, match="not a frame dump"):
        slscan.read_dump(tmp_path)
    with pytest.raises(slscan.InputError, match="a calibration is needed"):
        slscan.Decoder(plane_dump / "patterns", None)  # type: ignore[arg-type]


@pytest.mark.parametrize("suffix", [".xml", ".json.gz"])
def test_a_calibration_converted_by_opencv_decodes_the_same(dump, decoder, plane_dump, tmp_path, suffix):
    src = cv2.FileStorage(str(plane_dump / "calibration.yaml"), cv2.FILE_STORAGE_READ)  # our own file: trusted
    out = cv2.FileStorage(str(tmp_path / f"cal{suffix}"), cv2.FILE_STORAGE_WRITE)
    for key in src.root().keys():
        node = src.getNode(key)
        if key.endswith("_size"):  # as a cv::Size: a FileStorage sequence [ w, h ]
            out.startWriteStruct(key, cv2.FILE_NODE_SEQ | cv2.FILE_NODE_FLOW)
            for v in node.mat().ravel():
                out.write("", int(v))
            out.endWriteStruct()
        else:
            out.write(key, node.mat() if node.isMap() else node.real())
    out.release()
    src.release()
    frames = dump.frame_sets()[0]
    other = slscan.Decoder(dump.patterns, tmp_path / f"cal{suffix}", dump.depth_range_mm)
    assert np.array_equal(other.decode(frames).depth, decoder.decode(frames).depth)
