"""Shared test helpers. Each area keeps its own fixtures in its own tests/<area>/conftest.py."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.fixture
def run_cli():
    """Run `slscan ARGS...` in a subprocess; returns CompletedProcess (text, captured)."""

    def run(*args: str, timeout: float = 120, **kw) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True, timeout=timeout, **kw
        )

    return run
