"""Fixtures of the decoder tests: small virtual-rig scenes rendered once per session."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # the `synth` helper next to the tests

SMALL = {"camera_size": (320, 240), "projector_size": (512, 384)}


@pytest.fixture(scope="session")
def small_rig():
    """factory(scene, **overrides) -> VirtualRig at 320x240 / 512x384, cached per arguments."""
    from drivers.sim.rig import VirtualRig

    cache: dict = {}

    def make(scene: str, **overrides):
        key = (scene, tuple(sorted(overrides.items())))
        if key not in cache:
            cache[key] = VirtualRig.from_preset(scene, **{**SMALL, **overrides})
        return cache[key]

    return make


@pytest.fixture(scope="session")
def run_cli_module():
    """run(*args) -> the CompletedProcess of `python -m app.cli ARGS` (a fresh process: its own numba state)."""

    def run(*args):
        return subprocess.run(
            [sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True, timeout=300
        )

    return run
