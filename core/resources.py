"""Where the presets are: the repository's config/ folder, or its copy inside an installed slscan.

config/ holds the default configuration (sim.yaml, the virtual rig), the other bundled configs and the virtual
rig's scene presets (config/scenes/). A wheel carries it as the package data folder core/config/ (setup.py);
a checkout (or an editable install) has it at the top of the repository. One of the two exists.
"""

from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent


def _config_dir() -> Path:
    installed = _HERE / "config"
    return installed if (installed / "sim.yaml").is_file() else _HERE.parent / "config"


CONFIG_DIR = _config_dir()
SCENES_DIR = CONFIG_DIR / "scenes"
