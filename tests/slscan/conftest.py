"""Fixtures of the public API's tests: one small rendered dump (virtual rig, with ground truth) per session."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def plane_dump(tmp_path_factory) -> Path:
    """Two cycles of two-shot on the plane at 720 mm, 320x240 camera, 1024x768 projector: 4 frames, 3 sliding
    pairs; ground truth in DUMP/ground_truth/."""
    out = tmp_path_factory.mktemp("api") / "plane"
    cmd = [sys.executable, "-m", "app.cli", "sim", "render", "--scene", "plane", "--scheme", "two-shot"]
    cmd += ["--camera-size", "320x240", "--cycles", "2", "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT, timeout=120)
    return out
