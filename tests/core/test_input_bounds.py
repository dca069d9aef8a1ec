"""Inputs bounded where they are read (YAML nesting and size, infinite numbers, window tables): one line, exit 2."""

from __future__ import annotations

import pytest

from app.cli import main
from core.dump import read_dump
from core.errors import InputError
from core.yamlfile import MAX_DEPTH, load_yaml, parse_yaml

DEEP = "a: " + "[" * 3000 + "]" * 3000 + "\n"


def test_nesting_beyond_the_bound_is_a_yaml_error_not_a_recursion_error(tmp_path):
    ok = "a: " + "[" * (MAX_DEPTH - 2) + "1" + "]" * (MAX_DEPTH - 2)
    assert parse_yaml(ok)["a"] is not None
    path = tmp_path / "deep.yaml"
    path.write_text(DEEP)
    with pytest.raises(InputError, match=rf"deep.yaml: not valid YAML \(nested deeper than {MAX_DEPTH} levels\)"):
        load_yaml(path)


def test_a_deeply_nested_dump_index_or_config_is_one_line_exit_2(tmp_path, capsys):
    dump = tmp_path / "dump"
    dump.mkdir()
    (dump / "dump.yaml").write_text("format: slscan-dump\nversion: 1\n" + DEEP)
    with pytest.raises(InputError, match="nested deeper"):
        read_dump(dump)
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(DEEP)
    assert main(["live", "--headless", "--frames", "2", "--config", str(cfg)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cfg.yaml" in err[0] and "nested deeper" in err[0], err


def test_frame_ids_that_overflow_and_an_infinite_depth_range_are_refused(tmp_path):
    dump = tmp_path / "dump"
    dump.mkdir()
    head = "format: slscan-dump\nversion: 1\nscheme: two-shot\npatterns: patterns\n"
    (dump / "dump.yaml").write_text(head + "frames:\n- {file: f.png, pattern: 0, frame_id: .inf, timestamp_ns: 0}\n")
    with pytest.raises(InputError, match=r"frames\[0\]\.frame_id must be a whole number, found inf"):
        read_dump(dump)
    (dump / "dump.yaml").write_text(head + "depth_range_mm: [600, .inf]\nframes:\n")
    with pytest.raises(InputError, match="depth_range_mm"):
        read_dump(dump)


def test_a_window_length_whose_table_no_machine_holds_is_refused_naming_k(tmp_path, capsys):
    # 4**16 keys (16 GB of table) for two-shot GB, 8**12 for RGB: refused before any allocation
    base = ["patterns", "--scheme", "two-shot", "--size", "640x480"]
    assert main([*base, "--k", "16", "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "k=16 with 4 codes" in err[0] and "at most k=12" in err[0], err
    args = ["--channels", "RGB", "--k", "12", "--out", str(tmp_path / "q")]
    assert main([*base, *args]) == 2
    assert "k=12 with 8 codes" in capsys.readouterr().err
