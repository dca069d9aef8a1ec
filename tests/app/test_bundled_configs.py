"""`--config NAME` names a config that comes with slscan, from any folder; a file of that name wins."""

from __future__ import annotations

import pytest

from app.config import bundled_configs, load_config
from core.errors import InputError
from core.resources import CONFIG_DIR


def test_a_bare_name_is_a_bundled_config_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert {"sim", "sim_turntable", "rig.example"} <= set(bundled_configs())
    assert load_config("sim_turntable").path == CONFIG_DIR / "sim_turntable.yaml"
    assert load_config("sim.yaml").path == CONFIG_DIR / "sim.yaml"
    (tmp_path / "sim.yaml").write_text("rig: {camera: {driver: sim}}\n")
    assert load_config("sim.yaml").path.resolve() == tmp_path / "sim.yaml"  # the user's own file first


def test_an_unknown_config_lists_the_bundled_ones(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match=r"^nope: config file not found \(bundled configs: .*sim_turntable"):
        load_config("nope")
    with pytest.raises(InputError, match="config file not found"):
        load_config(tmp_path / "sub" / "sim.yaml")  # a path is a path: never a bundled config
