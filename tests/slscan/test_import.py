"""`import slscan` finds slscan's own layers whatever the working directory holds (a user's app.py)."""

from __future__ import annotations

import subprocess
import sys

import slscan

from .conftest import ROOT


def run_python(cwd, *args: str) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "NUMBA_CACHE_DIR": "/tmp/numba-slscan-import"}
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=120)


def test_the_public_names_are_there():
    assert slscan.__version__.count(".") == 2
    for name in ("read_dump", "Decoder", "Scanner", "Scan", "FrameSet", "Calibration", "InputError", "DeviceError"):
        assert hasattr(slscan, name), name
    assert set(slscan.__all__) <= set(dir(slscan))


def test_a_users_app_py_and_core_py_in_the_working_directory_do_not_break_it(tmp_path):
    (tmp_path / "app.py").write_text("raise SystemExit('the user app.py was imported as a package')\n")
    (tmp_path / "core.py").write_text("raise SystemExit('the user core.py was imported')\n")
    code = "import slscan, app, core; print(app.__file__); print(core.__file__); print(slscan.Decoder)"
    res = run_python(tmp_path, "-c", code)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[:2] == [str(ROOT / "app" / "__init__.py"), str(ROOT / "core" / "__init__.py")]


def test_a_script_named_app_py_can_import_it(tmp_path):
    (tmp_path / "app.py").write_text("import slscan\nprint(slscan.read_dump.__module__)\n")
    res = run_python(tmp_path, "app.py")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "slscan.dump"


def test_a_module_named_app_imported_first_is_named_in_one_line(tmp_path):
    (tmp_path / "app.py").write_text("VALUE = 1\n")
    res = run_python(tmp_path, "-c", "import app\ntry:\n    import slscan\nexcept ImportError as e:\n    print(e)")
    assert res.returncode == 0, res.stderr
    line = res.stdout.strip()
    assert "\n" not in line
    assert line.startswith("slscan: the module 'app' imported before slscan") and str(tmp_path / "app.py") in line
