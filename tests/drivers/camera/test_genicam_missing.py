"""Without the genicam / harvesters packages (no wheel for macOS on arm64) slscan works, and a GenICam camera
asked for says in one line which package is missing. The packages are hidden in a subprocess (sys.modules[name]
= None makes their import fail), so this process's Harvester is untouched."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

HIDE = "import sys\nsys.modules['genicam'] = sys.modules['harvesters'] = None\nfrom app.cli import main\n"


def run_without_genicam(*args: str) -> subprocess.CompletedProcess:
    code = HIDE + f"sys.exit(main({list(args)!r}))"
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("spec", ["genicam:cti=viky", "genicam:serial=2"])
def test_a_genicam_camera_without_the_package_is_one_line(tmp_path, spec):
    res = run_without_genicam("grab", "--camera", spec, "--frames", "1", "--out", str(tmp_path / "g"))
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr
    assert "GenICam cameras need the Python package 'genicam', which is not installed" in lines[0]


def test_everything_else_works_without_it():
    res = run_without_genicam("sim", "scenes")
    assert res.returncode == 0 and "plane" in res.stdout, res.stderr
    res = run_without_genicam("devices", "--cti", "viky")
    assert res.returncode == 0, res.stderr
    assert "'genicam', which is not installed" in res.stdout + res.stderr
