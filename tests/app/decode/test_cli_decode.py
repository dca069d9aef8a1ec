"""`slscan decode` on dumps written with the virtual rig, and its one-line errors on bad inputs."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import yaml

from app.dump import DumpWriter
from app.export import read_ply
from app.imageio import read_float_tiff, read_rgb, write_rgb
from app.patterns import two_shot_patterns


@pytest.fixture(scope="module")
def rig_dump(tmp_path_factory, small_rig):
    rig = small_rig("plane")
    folder = tmp_path_factory.mktemp("d") / "dump"
    ps = two_shot_patterns(rig.projector_size)
    cal = rig.calibration
    with DumpWriter(folder, ps, cal, rig.depth_range_mm) as w:
        for i, p in enumerate([1, 0, 1, 0]):  # starts with the inverse pattern: reversed pairs too
            w.add(rig.render(ps.images[p]), p, 100 + i, 1000 * i)
    return folder, rig


def copy(src, tmp_path):
    dst = tmp_path / "dump"
    shutil.copytree(src, dst)
    return dst


def test_decode_dump_writes_depth_cloud_and_stripes(rig_dump, tmp_path, run_cli):
    folder, rig = rig_dump
    out = tmp_path / "out"
    r = run_cli("decode", folder, "--out", out, "--workers", "1", "--png16", "--preview")
    assert r.returncode == 0, r.stderr
    assert "decoded 3 two-shot frame set(s)" in r.stdout
    gt = rig.ground_truth
    for n in range(3):
        depth = read_float_tiff(out / f"depth_{n:06d}.tiff")
        assert depth.shape == gt.depth.shape
        ok = depth > 0
        assert ok.mean() > 0.9
        assert np.sqrt(np.mean((depth[ok] - gt.depth[ok]) ** 2)) < 1.0
        cloud = read_ply(out / f"cloud_{n:06d}.ply")
        assert len(cloud.xyz) == ok.sum()
        assert np.allclose(np.sort(cloud.xyz[:, 2]), np.sort(depth[ok]))
        assert read_rgb(out / f"stripes_{n:06d}.png").shape == (*depth.shape, 3)
        assert (out / f"depth_{n:06d}.png").is_file() and (out / f"preview_{n:06d}.png").is_file()


@pytest.mark.parametrize("segmentation", ["events", "both"])
def test_decode_with_another_segmentation(rig_dump, tmp_path, run_cli, segmentation):
    folder, rig = rig_dump
    out = tmp_path / "out"
    r = run_cli("decode", folder, "--out", out, "--workers", "1", "--segmentation", segmentation)
    assert r.returncode == 0, r.stderr
    depth = read_float_tiff(out / "depth_000000.tiff")
    ok = depth > 0
    assert ok.mean() > 0.9 and np.sqrt(np.mean((depth[ok] - rig.ground_truth.depth[ok]) ** 2)) < 1.0


def test_decode_refuses_an_unknown_segmentation(rig_dump, tmp_path, run_cli):
    r = run_cli("decode", rig_dump[0], "--out", tmp_path / "out", "--segmentation", "edges")
    one_line_error(r, "--segmentation")
    assert not (tmp_path / "out").exists()


def test_gap_and_bad_tags_are_skipped(rig_dump, tmp_path, run_cli):
    folder, _ = rig_dump
    d = copy(folder, tmp_path)
    index = d / "dump.yaml"
    text = index.read_text().replace("frame_id: 102", "frame_id: 107").replace("frame_id: 103", "frame_id: 108")
    index.write_text(text)
    r = run_cli("decode", d, "--out", tmp_path / "out", "--workers", "1")
    assert r.returncode == 0, r.stderr
    assert "decoded 2 two-shot frame set(s)" in r.stdout and "1 frame_id gap" in r.stdout


def one_line_error(r, *words):
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_dump_without_patterns_yaml(rig_dump, tmp_path, run_cli):
    d = copy(rig_dump[0], tmp_path)
    (d / "patterns" / "patterns.yaml").unlink()
    one_line_error(run_cli("decode", d, "--out", tmp_path / "o"), "patterns.yaml")


def test_frames_of_different_sizes(rig_dump, tmp_path, run_cli):
    d = copy(rig_dump[0], tmp_path)
    write_rgb(d / "frames/000001.png", np.zeros((100, 100, 3), np.uint8))
    one_line_error(run_cli("decode", d, "--out", tmp_path / "o", "--workers", "1"), "differ in size")


def test_corrupt_png(rig_dump, tmp_path, run_cli):
    d = copy(rig_dump[0], tmp_path)
    (d / "frames/000000.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    one_line_error(run_cli("decode", d, "--out", tmp_path / "o", "--workers", "1"), "000000.png")
    assert not (tmp_path / "o").exists()  # nothing half-written


def test_calibration_size_mismatch(rig_dump, tmp_path, run_cli):
    d = copy(rig_dump[0], tmp_path)
    text = (d / "calibration.yaml").read_text()
    (d / "calibration.yaml").write_text(text.replace("data: [ 320, 240 ]", "data: [ 640, 480 ]"))
    one_line_error(run_cli("decode", d, "--out", tmp_path / "o", "--workers", "1"), "camera_size")


def test_frame_count_not_fitting_the_scheme(rig_dump, tmp_path, run_cli):
    d = copy(rig_dump[0], tmp_path)
    meta = yaml.safe_load((d / "dump.yaml").read_text())
    assert len(meta["frames"]) == 4
    meta["frames"] = meta["frames"][:1]  # one frame: no two-shot pair
    (d / "dump.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    one_line_error(run_cli("decode", d, "--out", tmp_path / "o"), "no complete two-shot frame set")


def test_all_black_frames_give_empty_depth_and_a_warning(rig_dump, tmp_path, run_cli):
    d = copy(rig_dump[0], tmp_path)
    for n in range(4):
        write_rgb(d / f"frames/{n:06d}.png", np.zeros((240, 320, 3), np.uint8))
    r = run_cli("decode", d, "--out", tmp_path / "o", "--workers", "1")
    assert r.returncode == 0
    assert "warning" in r.stderr and "empty depth" in r.stderr
    assert (read_float_tiff(tmp_path / "o" / "depth_000000.tiff") == 0).all()
