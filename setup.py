"""The one thing pyproject.toml cannot say: the repository's config/ folder goes into the wheel as core/config/.

The presets (config/sim.yaml, the scene presets in config/scenes/, ...) stay at the top of the repository, where
users and docs find them, and travel with an installed slscan as package data; core/resources.py looks for them
in either place. Folders without an __init__.py (drivers/trigger/firmware) are namespace packages, so their files
are package data too (pyproject.toml's package-data patterns). Everything else is in pyproject.toml.
"""

from setuptools import find_namespace_packages, setup

LAYERS = ["slscan", "app", "core", "drivers", "calibration"]
PRESETS = {"core.config": "config", "core.config.scenes": "config/scenes"}

setup(
    packages=[*find_namespace_packages(include=[p for n in LAYERS for p in (n, f"{n}.*")]), *PRESETS],
    package_dir=PRESETS,
    package_data={name: ["*.yaml"] for name in PRESETS},
)
