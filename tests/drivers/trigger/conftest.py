"""Trigger-box fixtures: the Python emulator on a pty, and the real firmware under simavr on a pty."""

from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from drivers.trigger.emulator import TriggerBoxEmulator

FIRMWARE_DIR = Path(__file__).resolve().parents[3] / "drivers" / "trigger" / "firmware"


@pytest.fixture
def emulator(tmp_path):
    """A fresh emulator (fresh pty: stale bytes linger in old ones) behind a stable link path."""
    with TriggerBoxEmulator(link=tmp_path / "ttyTRIG") as emu:
        yield emu


@pytest.fixture(scope="session")
def firmware_build(tmp_path_factory) -> Path:
    """Build trigger.elf and sim_host with avr-gcc / cc into a tmp dir (once per session)."""
    missing = [t for t in ("make", "avr-gcc", "cc", "pkg-config") if shutil.which(t) is None]
    if not Path("/usr/include/simavr/sim_avr.h").is_file():
        missing.append("libsimavr-dev")
    if missing:
        pytest.skip(f"trigger firmware tests need {', '.join(missing)} (installed by .ci/run)")
    out = tmp_path_factory.mktemp("trigger-fw")
    proc = subprocess.run(
        ["make", "-s", "-C", str(FIRMWARE_DIR), f"OUT={out}"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, f"firmware build failed:\n{proc.stdout}\n{proc.stderr}"
    return out


@dataclass
class Edge:
    cycle: int
    trig: int
    mark: int


class SimBox:
    """The firmware running in simavr; `port` is the MCU's UART as a pty."""

    def __init__(self, build: Path, tmp: Path, vsync_hz: float | None = None) -> None:
        tmp.mkdir(parents=True, exist_ok=True)
        self.edges_path = tmp / "edges.txt"
        cmd = [str(build / "sim_host"), str(build / "trigger.elf"), "--edges", str(self.edges_path)]
        if vsync_hz:
            cmd += ["--vsync", str(vsync_hz)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.port = ""
        deadline = time.monotonic() + 10
        buf = b""
        while not self.port:
            left = deadline - time.monotonic()
            assert left > 0 and self.proc.poll() is None, f"sim_host did not start: {buf!r}"
            if select.select([self.proc.stdout], [], [], left)[0]:
                chunk = os.read(self.proc.stdout.fileno(), 4096)
                buf += chunk
                for line in buf.decode(errors="replace").splitlines():
                    if line.startswith("PTY "):
                        self.port = line.split()[1]
        self.frequency = 16_000_000

    def reset(self) -> None:
        """A power glitch: simavr resets the MCU (EEPROM survives)."""
        os.kill(self.proc.pid, signal.SIGUSR1)

    def stop(self) -> tuple[list[Edge], int]:
        """Stop the simulation; return the TRIG edges and the final cycle count."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        edges, end = [], 0
        if self.edges_path.exists():
            for line in self.edges_path.read_text().splitlines():
                f = line.split()
                if f[0] == "END":
                    end = int(f[1])
                else:
                    edges.append(Edge(int(f[0]), int(f[1]), int(f[2])))
        return edges, end


@pytest.fixture
def simbox(firmware_build, tmp_path):
    box = SimBox(firmware_build, tmp_path)
    yield box
    box.stop()


@pytest.fixture
def simbox_factory(firmware_build, tmp_path):
    boxes: list[SimBox] = []

    def make(**kw) -> SimBox:
        box = SimBox(firmware_build, tmp_path / f"sim{len(boxes)}", **kw)
        boxes.append(box)
        return box

    yield make
    for b in boxes:
        b.stop()
