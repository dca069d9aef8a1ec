"""White-light texture frames in a dump: never paired (by this reader or one that does not know them), colouring
each decoded set from the nearest earlier one with the object's own colour, and their tag's one-line errors."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from app.dump import DumpWriter
from app.export import read_ply
from app.framesets import group_frame_sets
from app.imageio import read_float_tiff
from app.patterns import two_shot_patterns
from app.texture import texture_image, texture_index
from core.dump import read_dump
from core.scan_sidecar import read_scan_info

# capture order: T 0 1 0 T 1 0 (T = texture): sets (1,2), (2,3) after the first T, (5,6) after the second
TAGS = ["T", 0, 1, 0, "T", 1, 0]
FIRST_ID = 10


@pytest.fixture(scope="module")
def texture_dump(tmp_path_factory, small_rig):
    rig = small_rig("cube")
    ps = two_shot_patterns(rig.projector_size)
    folder = tmp_path_factory.mktemp("tex") / "dump"
    tex = texture_index(ps)
    white = rig.render(texture_image(ps))
    stripes = {p: rig.render(ps.images[p]) for p in (0, 1)}
    with DumpWriter(folder, ps, rig.calibration, rig.depth_range_mm, texture=True) as w:
        for i, t in enumerate(TAGS):
            w.add(white if t == "T" else stripes[t], tex if t == "T" else t, FIRST_ID + i, 16_666_667 * i)
    return folder, rig, white


@pytest.fixture(scope="module")
def decoded(texture_dump, tmp_path_factory, run_cli_module):
    folder, _, _ = texture_dump
    out = tmp_path_factory.mktemp("texout") / "out"
    r = run_cli_module("decode", folder, "--out", out, "--workers", "1")
    assert r.returncode == 0, r.stderr
    assert "decoded 3 two-shot frame set(s) from 7 frames" in r.stdout and "2 texture frame(s)" in r.stdout
    assert "bad tag" not in r.stdout
    return out


def test_no_reader_pairs_a_texture_frame(texture_dump):
    dump = read_dump(texture_dump[0])
    assert dump.texture_pattern == 2 and dump.texture_indices() == [0, 4]
    tags = [(f.frame_id, f.pattern) for f in dump.frames]
    sets, stats = group_frame_sets(tags, "two-shot", 2, texture_pattern=2)
    old_sets, old_stats = group_frame_sets(tags, "two-shot", 2)  # a reader that does not know texture frames
    assert sets == old_sets and [s.indices for s in sets] == [(1, 2), (3, 2), (6, 5)]
    assert stats.textures == 2 and stats.bad_tags == 0 and old_stats.bad_tags == 2
    assert all(i not in (0, 4) for s in sets for i in s.indices + ((s.previous,) if s.previous is not None else ()))


def test_each_set_is_coloured_by_the_nearest_earlier_texture_frame(texture_dump, decoded):
    _, _, white = texture_dump
    for n, texture_id in enumerate([FIRST_ID, FIRST_ID, FIRST_ID + 4]):
        info = read_scan_info(decoded / f"scan_{n:06d}.yaml")
        assert info.texture_frame_id == texture_id
        depth = read_float_tiff(decoded / info.files["depth"])
        cloud = read_ply(decoded / info.files["cloud"])
        np.testing.assert_array_equal(cloud.rgb, white[depth > 0])  # (the PLY's points: pixels with depth, row-major)


def _face_chroma(rig, depth: np.ndarray, rgb: np.ndarray) -> dict[int, np.ndarray]:
    """Per visible cube face, the median point colour made linear (the rig's camera gamma) and unmixed (the
    calibration's colour mixing), as r, g, b summing to 1: comparable with the face's albedo."""
    box = rig.scene.shapes[0]
    pts = rig.ground_truth.points[depth > 0].astype(np.float64)
    local = box.point_to_local(pts)
    half = np.asarray(box.half)
    on = np.all(np.abs(local) <= half + 0.5, axis=1)
    axis = np.argmax(np.abs(local) / half, axis=1)
    face = 2 * axis + (local[np.arange(len(pts)), axis] > 0)
    mixing = np.asarray(rig.calibration.color_mixing, np.float64)
    out = {}
    for f in np.unique(face[on]):
        sel = on & (face == f)
        if sel.sum() < 500:
            continue
        linear = (np.median(rgb[sel].astype(np.float64), axis=0) / 255.0) ** rig.options.camera_gamma
        albedo = np.linalg.solve(mixing, linear)
        out[int(f)] = albedo / albedo.sum()
    return out


def test_cloud_colours_are_the_objects_own_against_the_scene(texture_dump, decoded):
    """The cube's sticker colours (scene file) under white light; the pair's mean (no texture frame) is not."""
    folder, rig, _ = texture_dump
    faces = rig.scene.shapes[0].texture.faces
    depth = read_float_tiff(decoded / "depth_000000.tiff")
    textured = _face_chroma(rig, depth, read_ply(decoded / "cloud_000000.ply").rgb)
    assert len(textured) == 3  # blue, yellow and red faces in view
    for f, chroma in textured.items():
        albedo = np.asarray(faces[f]) / np.sum(faces[f])
        assert np.abs(chroma - albedo).max() < 0.1, (f, chroma, albedo)
    # the same set coloured from its own stripe frames (what a dump without texture frames gives)
    from app.decode.pipeline import FrameSetDecoder

    dump = read_dump(folder)
    dec = FrameSetDecoder("two-shot", dump.patterns_meta(), rig.calibration, rig.depth_range_mm)
    own = dec.decode([dump.load_frame(1), dump.load_frame(2)])
    wrong = _face_chroma(rig, own.depth, own.cloud.rgb)
    assert max(np.abs(wrong[f] - np.asarray(faces[f]) / np.sum(faces[f])).max() for f in wrong) > 0.15


@pytest.mark.parametrize(
    "value, words",
    [("0", ["texture_pattern", "number of pattern images"]), ("3", ["texture_pattern", "must be 2"]), ("x", ["'x'"])],
)
def test_a_malformed_texture_tag_names_the_field(texture_dump, tmp_path, value, words):
    from core.errors import InputError

    d = tmp_path / "dump"
    shutil.copytree(texture_dump[0], d)
    index = d / "dump.yaml"
    index.write_text(index.read_text().replace("texture_pattern: 2", f"texture_pattern: {value}"))
    with pytest.raises(InputError) as err:
        read_dump(d).texture_indices()
    message = str(err.value)
    assert "\n" not in message and "dump.yaml" in message and "texture_pattern" in message
    for w in words:
        assert w in message, message


def test_decode_refuses_a_texture_tag_on_a_pattern_in_one_line(texture_dump, tmp_path, run_cli_module):
    d = tmp_path / "dump"
    shutil.copytree(texture_dump[0], d)
    index = d / "dump.yaml"
    index.write_text(index.read_text().replace("texture_pattern: 2", "texture_pattern: 1"))
    r = run_cli_module("decode", d, "--out", tmp_path / "out")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "dump.yaml" in lines[0] and "texture_pattern" in lines[0], lines[0]
    assert not (tmp_path / "out").exists()
