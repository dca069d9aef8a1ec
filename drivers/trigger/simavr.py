"""The real trigger firmware, run under simavr with its UART on a pty (tests, demos, measurements).

    out = build_firmware(tmp_dir)          # avr-gcc + cc, via firmware/Makefile
    with SimulatedBox(out) as sim:         # sim.port is a /dev/pts/N that pyserial opens
        box = SerialTriggerBox(sim.port)
    edges, end_cycle = sim.edges()         # every TRIG edge, in simulated CPU cycles

`python -m drivers.trigger.simavr --rate 60 --seconds 5` measures the firmware's trigger rate
in simulated time (the crystal) and in wall-clock time (how closely simavr keeps real time).
"""

from __future__ import annotations

import argparse
import itertools
import os
import select
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from core.errors import DeviceError

FIRMWARE_DIR = Path(__file__).resolve().parent / "firmware"
F_CPU = 16_000_000


def missing_tools() -> list[str]:
    """What is missing to build and run the firmware here (empty when all is installed)."""
    missing = [t for t in ("make", "avr-gcc", "avr-objcopy", "cc", "pkg-config") if shutil.which(t) is None]
    if not Path("/usr/include/simavr/sim_avr.h").is_file():
        missing.append("libsimavr-dev")
    return missing


def build_firmware(out_dir: str | os.PathLike) -> Path:
    """trigger.elf, trigger.hex and sim_host into out_dir; returns out_dir."""
    missing = missing_tools()
    if missing:
        raise DeviceError(f"cannot build the trigger firmware: missing {', '.join(missing)} (see .ci/run)")
    out = Path(out_dir)
    proc = subprocess.run(
        ["make", "-s", "-C", str(FIRMWARE_DIR), f"OUT={out.resolve()}"], capture_output=True, text=True, timeout=300
    )
    if proc.returncode != 0:
        last = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["?"]
        raise DeviceError(f"trigger firmware build failed in {FIRMWARE_DIR}: {last[0]}")
    return out


@dataclass(frozen=True)
class Edge:
    cycle: int  # simulated CPU cycle of the TRIG (PB0) change
    trig: int  # TRIG level after the change
    mark: int  # MARK (PB1) level at the same moment


class SimulatedBox:
    """sim_host running trigger.elf; `port` is the MCU's UART. Stop it to read the edge log."""

    def __init__(self, build_dir: str | os.PathLike, vsync_hz: float | None = None, log_dir: str | None = None):
        build = Path(build_dir)
        self._tmp = None if log_dir else tempfile.TemporaryDirectory(prefix="sltrig-")
        self.edges_path = Path(log_dir or self._tmp.name) / "edges.txt"
        cmd = [str(build / "sim_host"), str(build / "trigger.elf"), "--edges", str(self.edges_path)]
        if vsync_hz:
            cmd += ["--vsync", repr(float(vsync_hz))]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.port = self._wait_for_pty(10.0)

    def _wait_for_pty(self, timeout_s: float) -> str:
        deadline, buf = time.monotonic() + timeout_s, b""
        while self.proc.poll() is None and time.monotonic() < deadline:
            if select.select([self.proc.stdout], [], [], 0.1)[0]:
                buf += os.read(self.proc.stdout.fileno(), 4096)
                for line in buf.decode(errors="replace").splitlines():
                    if line.startswith("PTY "):
                        return line.split()[1]
        self.stop()
        raise DeviceError(f"sim_host did not start: {buf.decode(errors='replace').strip()[-200:]}")

    def reset(self) -> None:
        """A power glitch: the MCU resets, EEPROM (the boot counter) survives."""
        os.kill(self.proc.pid, signal.SIGUSR1)

    def pause(self) -> None:
        """The MCU hangs: the port stays open but nothing answers."""
        os.kill(self.proc.pid, signal.SIGSTOP)

    def resume(self) -> None:
        os.kill(self.proc.pid, signal.SIGCONT)

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGCONT)
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for f in (self.proc.stdout, self.proc.stderr):
            if f:
                f.close()

    def edges(self) -> tuple[list[Edge], int]:
        """Stop the simulation; return every TRIG edge and the last simulated cycle."""
        self.stop()
        edges, end = [], 0
        if self.edges_path.exists():
            for line in self.edges_path.read_text().splitlines():
                f = line.split()
                if f[0] == "END":
                    end = int(f[1])
                else:
                    edges.append(Edge(int(f[0]), int(f[1]), int(f[2])))
        return edges, end

    def close(self) -> None:
        self.stop()
        if self._tmp is not None:
            self._tmp.cleanup()

    def __enter__(self) -> SimulatedBox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def measure_rate(build_dir: Path, rate_hz: float, seconds: float) -> dict[str, float]:
    """Run the firmware at rate_hz through the driver; the rate in simulated and in wall-clock time."""
    from drivers.trigger.serial_box import SerialTriggerBox

    with SimulatedBox(build_dir) as sim:
        with SerialTriggerBox(sim.port, source="int") as box:
            box.start(rate_hz)
            first = box.next_event(2.0)
            last = first
            t_end = time.monotonic() + seconds
            while time.monotonic() < t_end:
                last = box.next_event(2.0)
            box.stop()
            missed = box.missed_events
        rises = [e.cycle for e in sim.edges()[0] if e.trig]
    sim_hz = (len(rises) - 1) * F_CPU / (rises[-1] - rises[0])
    wall_hz = (last.count - first.count) / ((last.host_timestamp_ns - first.host_timestamp_ns) / 1e9)
    periods = [b - a for a, b in itertools.pairwise(rises)]
    return {
        "set_hz": rate_hz,
        "pulses": len(rises),
        "sim_hz": sim_hz,
        "sim_error_ppm": (sim_hz / rate_hz - 1) * 1e6,
        "sim_period_jitter_us": (max(periods) - min(periods)) / F_CPU * 1e6,
        "wall_hz": wall_hz,
        "wall_error_pct": (wall_hz / rate_hz - 1) * 100,
        "events_missed": missed,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, action="append", help="Hz (repeatable); default 60 and 59.94")
    ap.add_argument("--seconds", type=float, default=5.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="sltrig-build-") as tmp:
        build = build_firmware(tmp)
        for hz in args.rate or [60.0, 59.94]:
            r = measure_rate(build, hz, args.seconds)
            print(
                f"set {r['set_hz']:g} Hz: {r['pulses']} pulses; simulated time {r['sim_hz']:.6f} Hz "
                f"({r['sim_error_ppm']:+.2f} ppm, period jitter {r['sim_period_jitter_us']:.2f} us); "
                f"wall clock {r['wall_hz']:.3f} Hz ({r['wall_error_pct']:+.2f} %); "
                f"event lines lost {r['events_missed']}"
            )


if __name__ == "__main__":
    main()
