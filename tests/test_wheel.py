"""The wheel installs and runs without the repository: built, installed into a fresh venv, run from a temp folder.

The venv sees the system's site-packages for the dependencies (numpy, OpenCV, numba: installing them again would
take minutes), and slscan is installed into it from the wheel with --ignore-installed, so the venv's own copy is
the one imported (checked). `.ci/run` does the full check: a venv without system packages, `slscan live
--headless --frames 60` and `slscan decode` in it (a cold numba compile, over a minute).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run(*cmd: str | Path, cwd: Path, timeout: float = 60) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    res = subprocess.run(list(map(str, cmd)), cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{cmd}: {res.stderr[-2000:]}"
    return res


def source_tree(dest: Path) -> Path:
    """The repository's files as git knows them (tracked, or new and not ignored): what a clone builds from, and no
    build/ folder left in the checkout."""
    listed = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, capture_output=True, check=True
    ).stdout.split(b"\0")
    for rel in filter(None, (name.decode() for name in listed)):
        if (ROOT / rel).is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, dest / rel)
    return dest


@pytest.mark.slow
def test_the_wheel_runs_from_any_folder(tmp_path):
    dist, env_dir, elsewhere = tmp_path / "dist", tmp_path / "venv", tmp_path / "elsewhere"
    elsewhere.mkdir()
    src = source_tree(tmp_path / "src")
    # (build isolation fetches the setuptools pyproject.toml asks for; the wheel holds no compiled code)
    run(sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", dist, src, cwd=tmp_path, timeout=120)
    (wheel,) = dist.glob("slscan-*.whl")
    venv.create(env_dir, system_site_packages=True, with_pip=False)
    py = env_dir / "bin" / "python"
    run(sys.executable, "-m", "pip", "--python", py, "install", "-q", "--no-deps", "--ignore-installed", wheel,
        cwd=tmp_path)  # fmt: skip
    where = run(py, "-c", "import slscan, app, core.resources as r; print(app.__file__); print(r.CONFIG_DIR)",
                cwd=elsewhere).stdout.split()  # fmt: skip
    site = env_dir / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    assert where == [str(site / "app" / "__init__.py"), str(site / "core" / "config")]
    scenes = run(env_dir / "bin" / "slscan", "sim", "scenes", cwd=elsewhere).stdout
    assert {"face", "plane", "turntable"} <= {line.split()[0] for line in scenes.splitlines()}
    usage = run(env_dir / "bin" / "slscan", "live", "--help", cwd=elsewhere).stdout
    assert "--headless" in usage
