"""Trigger-box fixtures: the Python emulator on a pty, and the real firmware under simavr on a pty."""

from __future__ import annotations

import pytest

from drivers.trigger.emulator import TriggerBoxEmulator
from drivers.trigger.simavr import SimulatedBox, build_firmware, missing_tools


@pytest.fixture
def emulator(tmp_path):
    """A fresh emulator (fresh pty: stale bytes linger in old ones) behind a stable link path."""
    with TriggerBoxEmulator(link=tmp_path / "ttyTRIG") as emu:
        yield emu


@pytest.fixture(scope="session")
def firmware_build(tmp_path_factory):
    """trigger.elf + sim_host, built once per session with avr-gcc / cc into a tmp dir."""
    missing = missing_tools()
    if missing:
        pytest.skip(f"trigger firmware tests need {', '.join(missing)} (installed by .ci/run)")
    return build_firmware(tmp_path_factory.mktemp("trigger-fw"))


@pytest.fixture
def simbox_factory(firmware_build, tmp_path):
    """Start the firmware under simavr: make(vsync_hz=None) -> SimulatedBox (stopped at teardown)."""
    boxes: list[SimulatedBox] = []

    def make(vsync_hz: float | None = None) -> SimulatedBox:
        log_dir = tmp_path / f"sim{len(boxes)}"
        log_dir.mkdir()
        boxes.append(SimulatedBox(firmware_build, vsync_hz=vsync_hz, log_dir=str(log_dir)))
        return boxes[-1]

    yield make
    for b in boxes:
        b.close()


@pytest.fixture
def simbox(simbox_factory):
    return simbox_factory()
