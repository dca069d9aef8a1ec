"""`slscan patterns`: writes what patterns.yaml says; bad input is one line, exit 2, nothing half-written."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
import yaml

from app.cli import build_parser, main
from core.imageio import read_rgb
from core.pattern_export import read_patterns
from core.patterns import graycode_patterns, one_shot_patterns, two_shot_patterns


@pytest.mark.parametrize(
    ("scheme", "expected"),
    [
        ("two-shot", lambda: two_shot_patterns((320, 40))),
        ("one-shot", lambda: one_shot_patterns((320, 40))),
        ("graycode", lambda: graycode_patterns((320, 40))),
    ],
)
def test_cli_writes_what_patterns_yaml_says(tmp_path, capsys, scheme, expected):
    out = tmp_path / "pat"
    assert main(["patterns", "--scheme", scheme, "--size", "320x40", "--out", str(out)]) == 0
    meta = yaml.safe_load((out / "patterns.yaml").read_text())
    assert meta["scheme"] == scheme and meta["size"] == [320, 40]
    ref = expected()
    assert meta["images"] == ref.names
    assert sorted(p.name for p in out.iterdir()) == sorted([*ref.names, "patterns.yaml"])
    for name, img in zip(ref.names, ref.images, strict=True):
        got = read_rgb(out / name)
        assert got.dtype == np.uint8 and got.shape == (40, 320, 3)
        assert np.array_equal(got, img), name
    back = read_patterns(out)
    assert back.params == ref.params
    assert "wrote" in capsys.readouterr().out


def test_stripe_width_and_channels_options(tmp_path):
    out = tmp_path / "p"
    args = ["patterns", "--scheme", "two-shot", "--size", "64x8", "--channels", "RG", "--stripe-width", "3"]
    assert main([*args, "--k", "5", "--out", str(out)]) == 0
    meta = yaml.safe_load((out / "patterns.yaml").read_text())
    assert meta["channels"] == "RG" and meta["stripe_width"] == 3 and meta["k"] == 5
    f1 = read_rgb(out / "frame1.png")
    assert not f1[..., 2].any()  # blue unused
    whole = f1[:, :63]  # 21 whole stripes of 3 px: all three columns of a stripe are equal
    assert np.array_equal(whole[:, 0::3], whole[:, 1::3]) and np.array_equal(whole[:, 0::3], whole[:, 2::3])


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--scheme", "three-shot", "--size", "64x8"], "invalid choice"),
        (["--scheme", "two-shot", "--size", "64by8"], "not WxH"),
        (["--scheme", "two-shot", "--size", "6x8"], "too narrow"),
        (["--scheme", "two-shot", "--size", "64x8", "--k", "0"], "out of range"),
        (["--scheme", "one-shot", "--size", "64x8", "--colors", "R"], "out of range"),
        (["--scheme", "two-shot", "--size", "64x8", "--channels", "GG"], "channels"),
    ],
)
def test_bad_input_is_one_line_exit_2_nothing_written(run_cli, tmp_path, args, words):
    out = tmp_path / "out"
    r = run_cli("patterns", *args, "--out", out)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert words in lines[0] and "Traceback" not in r.stderr
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary leftovers either


def test_unwritable_output_is_one_line(run_cli, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    r = run_cli("patterns", "--scheme", "two-shot", "--size", "64x8", "--out", blocker / "sub")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_existing_output_is_not_overwritten_without_force(run_cli, tmp_path):
    out = tmp_path / "p"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    r = run_cli("patterns", "--scheme", "two-shot", "--size", "64x8", "--out", out)
    assert r.returncode == 2 and "not empty" in r.stderr
    assert (out / "keep.txt").read_text() == "precious"
    r = run_cli("patterns", "--scheme", "two-shot", "--size", "64x8", "--out", out, "--force")
    assert r.returncode == 0 and (out / "frame1.png").is_file() and not (out / "keep.txt").exists()


def test_every_subcommand_has_useful_help(run_cli):
    r = run_cli("--help")
    assert r.returncode == 0 and "patterns" in r.stdout and "virtual rig" in r.stdout
    (action,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    commands = sorted(action.choices)
    assert "patterns" in commands
    for name in commands:
        h = run_cli(name, "--help")
        assert h.returncode == 0, name
        assert len(h.stdout.splitlines()) >= 4, name
