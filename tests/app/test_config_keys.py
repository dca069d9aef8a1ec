"""A config key slscan does not know is an error naming it and the nearest known one (a typo used to be ignored)."""

from __future__ import annotations

import pytest
import yaml

import slscan
from app.cli import main
from app.config import DEFAULT_CONFIG, load_config

CASES = {
    "top level": (lambda d: d.update(captur=d.pop("capture")), "key 'captur' is unknown: did you mean 'capture'?"),
    "scheme": (lambda d: d["scheme"].update(chanels="GB"), "'scheme.chanels' is unknown: did you mean 'scheme.chan"),
    "capture": (lambda d: d["capture"].update(rate=60), "'capture.rate' is unknown: did you mean 'capture.rate_hz'?"),
    "rig": (lambda d: d["rig"].update(projecter={}), "key 'rig.projecter' is unknown: did you mean 'rig.projector'?"),
    "sim": (lambda d: d["sim"].update(scen="plane"), "key 'sim.scen' is unknown: did you mean 'sim.scene'?"),
    "nothing near": (lambda d: d.update(zzz=1), "key 'zzz' is unknown (known: board, calibration, capture,"),
    "driver option": (
        lambda d: d["rig"].update(camera={"driver": "v4l2", "devise": 0}, projector={"driver": "sim"}),
        "key 'rig.camera.devise' is unknown to its driver: did you mean 'rig.camera.device'?",
    ),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_mistyped_key_is_one_line_with_the_nearest_known_one(tmp_path, capsys, name):
    edit, words = CASES[name]
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    edit(data)
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["live", "--headless", "--frames", "1", "--config", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and words in err, err


def test_every_bundled_config_passes():
    for path in sorted(DEFAULT_CONFIG.parent.glob("*.yaml")):
        load_config(path)


def test_a_scanner_config_mapping_is_checked_too():
    with pytest.raises(slscan.InputError, match=r"<config mapping>: key 'shceme' is unknown: did you mean 'scheme'\?"):
        slscan.Scanner({"shceme": {"name": "two-shot"}})
