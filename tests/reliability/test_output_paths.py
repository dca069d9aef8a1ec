"""Outputs: never written or removed through a symlink; file system refusals are one line, exit 2."""

from __future__ import annotations

import os


def test_an_output_folder_that_is_a_symlink_is_refused_and_its_target_untouched(run_cli, tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    (real / "keep.txt").write_text("recorded data")
    link = tmp_path / "link"
    os.symlink(real, link)
    r = run_cli("patterns", "--scheme", "two-shot", "--size", "64x48", "--out", link, "--force")
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [f"slscan patterns: error: {link}: is a symlink; give the folder itself"]
    assert [p.name for p in real.iterdir()] == ["keep.txt"] and link.is_symlink()


def test_a_name_the_file_system_refuses_is_one_line_exit_2(run_cli, tmp_path):
    r = run_cli("patterns", "--scheme", "two-shot", "--size", "64x48", "--out", tmp_path / ("x" * 300))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("slscan patterns: error:") and "too long" in lines[0], lines
