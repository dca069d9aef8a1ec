"""Fuzzing the readers of every file slscan reads: any bytes give a result or an InputError, nothing else.

Mutations start from real, valid files so the fuzzer reaches deep into the parsers.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.calibration import Calibration
from core.dump import DumpWriter, read_dump
from core.errors import InputError
from core.pattern_export import read_patterns_meta, write_patterns
from core.patterns import two_shot_patterns

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
    # Whatever was accepted stays inside the folder and is loadable.
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
