"""Camera test fixtures: a small frame dump with known pixels and tags."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from core.dump import DumpWriter
from core.patterns import make_patterns

FRAME_IDS = [100, 101, 102, 104, 105, 106]  # a gap (103): ids must come back as recorded
STEP_NS = 50_000_000


def frame_image(i: int, bits: int = 8) -> np.ndarray:
    img = np.zeros((24, 32, 3), np.uint16 if bits == 16 else np.uint8)
    img[..., 0] = 10 * i + 1
    img[..., 1] = np.arange(32)[None, :]
    img[..., 2] = np.arange(24)[:, None]
    if bits == 16:
        img *= 257
    return img


@pytest.fixture
def make_dump(tmp_path):
    def make(name: str = "dump", n: int = len(FRAME_IDS), bits: int = 8):
        folder = tmp_path / name
        pats = make_patterns("two-shot", (64, 48))
        with DumpWriter(folder, pats) as w:
            for i in range(n):
                w.add(frame_image(i, bits), pattern=i % 2, frame_id=FRAME_IDS[i], timestamp_ns=1_000_000 + i * STEP_NS)
        return folder

    return make


@pytest.fixture
def truth() -> SimpleNamespace:
    """What make_dump wrote: frame ids, timestamp step, and the image of frame i."""
    return SimpleNamespace(ids=FRAME_IDS, step=STEP_NS, image=frame_image)
