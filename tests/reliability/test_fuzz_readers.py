"""Fuzzing the readers of every file slscan reads: any bytes give a result or an InputError, nothing else.

Mutations start from real, valid files so the fuzzer reaches deep into the parsers.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.config import DEFAULT_CONFIG as BUNDLED_CONFIG
from app.config import load_config
from calibration.board import load_board
from calibration.capture import read_levels, write_levels
from core.calibration import Calibration
from core.dump import DumpWriter, read_dump
from core.errors import InputError
from core.pattern_export import read_patterns_meta, write_patterns
from core.patterns import two_shot_patterns
from drivers.sim.scene import SCENES_DIR, load_scene

SCENE_PRESET = SCENES_DIR / "face.yaml"

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def mutate(data: bytes, edits: list[tuple[int, int, bytes]]) -> bytes:
    """Apply (position, delete-count, insert) edits: truncation, garbage, deletions, duplications."""
    buf = bytearray(data)
    for pos, delete, insert in edits:
        pos = pos % (len(buf) + 1)
        buf[pos : pos + delete] = insert
    return bytes(buf)


edits = st.lists(
    st.tuples(st.integers(0, 10_000), st.integers(0, 40), st.binary(max_size=12)),
    min_size=1,
    max_size=4,
)
yaml_tokens = st.sampled_from(
    [b":", b"- ", b"[", b"]", b"{", b"}", b"\n", b"  ", b"..", b"/", b"!!", b"&a", b"*a", b"'"]
)
token_edits = st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 8), yaml_tokens), min_size=1, max_size=5)


@pytest.fixture(scope="module")
def valid_dump(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fz") / "dump"
    K = [[400, 0, 15.5], [0, 400, 11.5], [0, 0, 1]]
    cal = Calibration((32, 24), K, [0] * 5, (64, 48), K, [0] * 5, np.eye(3), [-80, 0, 0], color_mixing=np.eye(3))
    with DumpWriter(folder, two_shot_patterns((64, 48)), cal, depth_range_mm=(200, 600)) as w:
        for i in range(4):
            w.add(np.full((24, 32, 3), 40 * i, np.uint8), i % 2, i + 1, 1000 * i)
    return folder


def check_dump_reader(folder, index_bytes: bytes, target) -> None:
    (folder / "dump.yaml").write_bytes(index_bytes)
    try:
        d = read_dump(folder)
    except InputError as exc:
        assert "\n" not in str(exc).strip()
        return
    # Whatever was accepted obeys the schema: ids increase, time never goes back, every value an int64 ...
    ids = [r.frame_id for r in d.frames]
    stamps = [r.timestamp_ns for r in d.frames]
    assert all(b > a for a, b in itertools.pairwise(ids))
    assert all(b >= a for a, b in itertools.pairwise(stamps))
    assert all(0 <= v < 2**63 for v in ids + stamps)
    # ... and stays inside the folder and is loadable.
    for i, rec in enumerate(d.frames):
        assert (folder / rec.file).resolve().is_relative_to(folder.resolve())
        if i < 2:
            try:
                d.load_frame(i)
            except InputError:
                pass


@FUZZ
@given(e=edits)
def test_fuzz_dump_index_bytes(valid_dump, tmp_path, e):
    original = (valid_dump / "dump.yaml").read_bytes()
    try:
        check_dump_reader(valid_dump, mutate(original, e), None)
    finally:
        (valid_dump / "dump.yaml").write_bytes(original)


@FUZZ
@given(e=token_edits)
def test_fuzz_dump_index_yaml_structure(valid_dump, e):
    original = (valid_dump / "dump.yaml").read_bytes()
    try:
        check_dump_reader(valid_dump, mutate(original, e), None)
    finally:
        (valid_dump / "dump.yaml").write_bytes(original)


@pytest.fixture(scope="module")
def valid_calibration(tmp_path_factory):
    path = tmp_path_factory.mktemp("fzc") / "c.yaml"
    K = [[400, 0, 15.5], [0, 400, 11.5], [0, 0, 1]]
    Calibration((32, 24), K, [0.1] * 5, (64, 48), K, [0] * 5, np.eye(3), [-80, 0, 0], {"camera_rms": 0.1}).save(path)
    return path.read_bytes()


@FUZZ
@given(e=st.one_of(edits, token_edits))
def test_fuzz_calibration_reader(valid_calibration, tmp_path, e):
    path = tmp_path / "c.yaml"
    path.write_bytes(mutate(valid_calibration, e))
    try:
        cal = Calibration.load(path)
    except InputError as exc:
        assert "c.yaml" in str(exc) and "\n" not in str(exc).strip()
        return
    assert cal.camera_matrix.shape == (3, 3) and np.isfinite(cal.R).all()
    for K in (cal.camera_matrix, cal.projector_matrix):  # what was accepted is a plausible pinhole
        assert K[1, 0] == K[2, 0] == K[2, 1] == 0 and K[0, 0] > 0 and K[1, 1] > 0
    assert np.abs(cal.camera_distortion).max() <= 1000


@pytest.fixture(scope="module")
def valid_patterns_yaml(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fzp")
    write_patterns(two_shot_patterns((64, 8), k=3), folder)
    return (folder / "patterns.yaml").read_bytes()


@FUZZ
@given(e=st.one_of(edits, token_edits))
def test_fuzz_patterns_yaml_reader(valid_patterns_yaml, tmp_path, e):
    (tmp_path / "patterns.yaml").write_bytes(mutate(valid_patterns_yaml, e))
    try:
        meta = read_patterns_meta(tmp_path)
    except InputError as exc:
        assert "patterns.yaml" in str(exc)
        return
    assert meta["scheme"] in ("one-shot", "two-shot", "graycode")


BOARD_YAML = b"type: charuco\nrows: 5\ncols: 7\nsquare_mm: 30\nmarker_mm: 22\ndictionary: DICT_5X5_100\n"


@FUZZ
@given(e=st.one_of(edits, token_edits))
def test_fuzz_board_reader(tmp_path, e):
    path = tmp_path / "board.yaml"
    path.write_bytes(
        mutate(b"type: charuco\nrows: 5\ncols: 7\nsquare_mm: 30\nmarker_mm: 22\ndictionary: DICT_5X5_100\n", e)
    )
    try:
        board = load_board(path)
    except InputError as exc:
        assert "board.yaml" in str(exc) and "\n" not in str(exc).strip()
        return
    assert 2 <= board.rows <= 200 and 2 <= board.cols <= 200 and 0 < board.square_mm < 10000


@pytest.fixture(scope="module")
def levels_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fzl") / "levels"
    write_levels(folder, [(c, v, np.full((4, 6, 3), v, np.uint8)) for c in "RGB" for v in (0, 128, 255)], 2.2)
    return folder


@FUZZ
@given(e=st.one_of(edits, token_edits))
def test_fuzz_levels_reader(levels_folder, e):
    path = levels_folder / "levels.yaml"
    original = path.read_bytes()
    path.write_bytes(mutate(original, e))
    try:
        levels = read_levels(levels_folder)
    except InputError as exc:
        assert "levels.yaml" in str(exc) or str(levels_folder) in str(exc)
        assert "\n" not in str(exc).strip()
        return
    finally:
        path.write_bytes(original)
    assert all(ch in "RGB" and 0 <= level <= 255 and img.ndim == 3 for ch, level, img in levels)


@FUZZ
@given(e=st.one_of(edits, token_edits))
def test_fuzz_config_reader(tmp_path, e):
    path = tmp_path / "cfg.yaml"
    path.write_bytes(mutate(BUNDLED_CONFIG.read_bytes(), e))
    try:
        cfg = load_config(path)
    except InputError as exc:
        assert "cfg.yaml" in str(exc) and "\n" not in str(exc).strip()
        return
    assert isinstance(cfg.data, dict)


@FUZZ
@given(e=st.one_of(edits, token_edits))
def test_fuzz_scene_preset_reader(tmp_path, e):
    path = tmp_path / "scene.yaml"
    path.write_bytes(mutate(SCENE_PRESET.read_bytes(), e))
    try:
        scene = load_scene(path)
    except InputError as exc:
        assert "scene.yaml" in str(exc) and "\n" not in str(exc).strip()
        return
    assert scene.shapes
