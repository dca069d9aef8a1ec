"""Operator mistakes in a rig config: one line naming the file and the key, exit status 2."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from app.cli import main
from app.config import DEFAULT_CONFIG


def config_with(tmp_path, edit) -> str:
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    edit(data)
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


CASES = {
    "unknown camera driver": (lambda d: d["rig"]["camera"].update(driver="nosuchcam"), "'rig.camera.driver'"),
    "unknown projector driver": (lambda d: d["rig"]["projector"].update(driver="beamer"), "'rig.projector.driver'"),
    "unknown trigger driver": (lambda d: d["rig"]["trigger"].update(driver="magic"), "'rig.trigger.driver'"),
    "missing camera": (lambda d: d["rig"].pop("camera"), "missing key 'rig.camera'"),
    "missing driver": (lambda d: d["rig"]["camera"].pop("driver"), "missing key 'rig.camera.driver'"),
    "missing rig": (lambda d: d.pop("rig"), "missing key 'rig'"),
    "bad scheme": (lambda d: d["scheme"].update(name="three-shot"), "'scheme.name'"),
    "bad rate": (lambda d: d["capture"].update(rate_hz="fast"), "'capture.rate_hz'"),
    "bad segmentation": (lambda d: d["scheme"].update(segmentation="edges"), "'scheme.segmentation'"),
    "bad depth range": (lambda d: d.update(depth_range_mm=[900, 100]), "'depth_range_mm'"),
    "unknown sim key": (lambda d: d["sim"].update(lens="fisheye"), "'sim.lens'"),
    "real rig without calibration": (
        lambda d: d["rig"].update(camera={"driver": "v4l2"}, projector={"driver": "pyglet"}, trigger="none"),
        "missing key 'calibration'",
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("command", ["live", "dump"])
def test_config_error_is_one_line_naming_file_and_key(tmp_path, capsys, name, command):
    edit, expected = CASES[name]
    path = config_with(tmp_path, edit)
    args = [command, "--config", path, "--frames", "5"]
    args += ["--headless"] if command == "live" else ["--out", str(tmp_path / "out")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert path in err and expected in err, err
    assert not (tmp_path / "out").exists()


def test_segmentation_from_the_config_reaches_the_decoder(tmp_path):
    from app.session import build_session

    session = build_session(config_with(tmp_path, lambda d: d["scheme"].update(segmentation="both")))
    assert session.processor().decoder.params.segmentation == "both"
    assert build_session().processor().decoder.params.segmentation == "runs"  # the default


def test_missing_config_file_and_cli_exit_status(tmp_path, run_cli):
    r = run_cli("live", "--headless", "--config", tmp_path / "nope.yaml")
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "nope.yaml" in r.stderr and "not found" in r.stderr
    assert "Traceback" not in r.stderr


def test_dump_refuses_to_overwrite(tmp_path, capsys):
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "keep.txt").write_text("mine")
    assert main(["dump", "--frames", "3", "--out", str(tmp_path / "rec")]) == 2
    assert "never overwritten" in capsys.readouterr().err
    assert (tmp_path / "rec" / "keep.txt").read_text() == "mine"


def test_rig_example_config_names_real_drivers_and_fails_on_the_missing_device(tmp_path):
    """config/rig.example.yaml: every driver it names is registered; without hardware, one clear device error."""
    import shutil

    from app.config import CONFIG_DIR
    from app.session import build_session
    from core.calibration import Calibration
    from core.errors import DeviceError, InputError

    rig = tmp_path / "rig.yaml"
    shutil.copy(CONFIG_DIR / "rig.example.yaml", rig)
    with pytest.raises(InputError, match=r"key 'calibration'.*not found"):
        build_session(rig)
    K = [[800, 0, 319.5], [0, 800, 239.5], [0, 0, 1]]
    Kp = [[1200, 0, 511.5], [0, 1200, 383.5], [0, 0, 1]]
    Calibration((640, 480), K, [0] * 5, (1024, 768), Kp, [0] * 5, np.eye(3), [-150, 0, 0]).save(
        tmp_path / "calibration.yaml"
    )
    session = build_session(rig)
    assert session.scheme == "two-shot" and session.patterns.size == (1024, 768)
    with pytest.raises(DeviceError, match="GenTL producer"):
        session.make_devices()
