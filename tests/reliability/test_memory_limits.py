"""Resource bounds under an address-space limit (`ulimit -v`): inputs that ask for more memory than the process
may take end in one line naming the input and exit status 2, never a traceback, and leave no output behind.

The CLI runs in a subprocess with RLIMIT_AS set before it starts (as `ulimit -v` does in a shell).
"""

from __future__ import annotations

import os
import resource
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np

from core.calibration import Calibration
from core.dump import DumpWriter
from core.patterns import two_shot_patterns

ROOT = Path(__file__).resolve().parents[2]
LIMIT_MB = 1200  # room for Python, numpy, OpenCV and numba (~0.7 GB of address space), not for 16384^2 images


def run_limited(*args: str, limit_mb: int = LIMIT_MB) -> subprocess.CompletedProcess:
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit_mb << 20, limit_mb << 20))

    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        preexec_fn=limit,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=120,
    )


def one_line(run: subprocess.CompletedProcess) -> str:
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def png_bomb(path: Path, w: int, h: int) -> None:
    """A valid RGB PNG of w x h black pixels: a few hundred KB on disk, w * h * 3 bytes once decoded."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    z = zlib.compressobj(9)
    row = bytes(1 + 3 * w)  # filter byte 0, then the row's zero pixels
    body = b"".join(z.compress(row) for _ in range(h)) + z.flush()
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", body) + chunk(b"IEND", b""))


def test_patterns_of_the_largest_size_are_one_line_under_a_memory_limit(tmp_path):
    out = tmp_path / "patterns"
    line = one_line(run_limited("patterns", "--scheme", "two-shot", "--size", "16384x16384", "--out", str(out)))
    assert "out of memory" in line
    assert not out.exists()


def test_a_png_bomb_in_a_dump_is_refused_from_its_header_under_a_memory_limit(tmp_path):
    dump = tmp_path / "dump"
    K = [[400, 0, 15.5], [0, 400, 11.5], [0, 0, 1]]
    cal = Calibration((32, 24), K, [0] * 5, (64, 48), K, [0] * 5, np.eye(3), [-80, 0, 0])
    with DumpWriter(dump, two_shot_patterns((64, 48)), cal) as w:
        for i in range(2):
            w.add(np.full((24, 32, 3), 60, np.uint8), i, i + 1, 1000 * i)
    bomb = dump / "frames" / "000000.png"
    png_bomb(bomb, 16000, 16000)  # 768 MB of pixels, then its RGB copy: more than the limit leaves
    assert bomb.stat().st_size < 2 << 20
    out = tmp_path / "grab"
    line = one_line(run_limited("grab", "--camera", f"replay:{dump}", "--frames", "2", "--out", str(out)))
    assert str(bomb) in line and "16000x16000" in line and "MB" in line
    assert not out.exists() or not any(out.iterdir())
