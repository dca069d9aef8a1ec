"""The session's decoder is compiled (or loaded from numba's cache) before frames arrive, and a slow first
compile is announced: a cold `slscan live` had spent its first 69 s compiling in the decode thread, holding the
GIL, with no depth maps and no word to the operator."""

from __future__ import annotations

import time

import numpy as np

from app.commands.live import build_session
from app.pipeline import Processor

from .conftest import SMALL


def _record_decodes(monkeypatch, delay_s: float = 0.0) -> list:
    """Every frame set Processor.decode_depth sees (shape and dtype of each frame), after delay_s."""
    seen: list = []
    real = Processor.decode_depth

    def spy(self, images):
        seen.append([(im.shape, im.dtype) for im in images])
        time.sleep(delay_s)
        return real(self, images)

    monkeypatch.setattr(Processor, "decode_depth", spy)
    return seen


def test_session_processor_decodes_a_blank_set_of_the_camera_size_and_dtype_first(monkeypatch, capsys):
    seen = _record_decodes(monkeypatch)
    session = build_session(None, sim_overrides={**SMALL, "bit_depth": 16})
    processor = session.processor()
    assert seen == [[((240, 320, 3), np.dtype(np.uint16))] * 2]
    # fast here (the test run's kernels are compiled): nothing said
    assert "compiling" not in capsys.readouterr().err
    # and the warmed decoder decodes the rig's frames to depth
    frames = [session.sim.rig.render(im) for im in session.patterns.images]
    _, depth, _ = processor.decode_depth(tuple(frames))
    assert depth.dtype == np.float32 and (depth > 0).mean() > 0.5


def test_a_slow_warm_up_is_announced_once_and_a_fast_one_is_not(monkeypatch, sim_session):
    processor = sim_session[1]
    calls: list[float] = []
    assert processor.warm_up(np.uint8, announce=lambda: calls.append(time.perf_counter()), after_s=5.0) < 5.0
    assert calls == []
    _record_decodes(monkeypatch, delay_s=0.4)
    t0 = time.perf_counter()
    took = processor.warm_up(np.uint8, announce=lambda: calls.append(time.perf_counter()), after_s=0.05)
    time.sleep(0.1)  # (a timer that was not cancelled would fire late)
    assert took >= 0.4 and len(calls) == 1 and calls[0] - t0 < 0.4


def test_the_announcement_names_the_scheme_on_stderr(capsys, sim_session):
    sim_session[0]._announce_compile()
    err = capsys.readouterr().err
    assert "compiling the two-shot decoder" in err and "first run only" in err


def test_a_replay_warms_up_for_its_dumps_frames_and_survives_an_unreadable_first_frame(tmp_path):
    from app.cli import main
    from app.commands.replay import replay_session
    from app.dump import read_dump

    out = tmp_path / "d16"
    args = ["sim", "render", "--scene", "plane", "--scheme", "two-shot", "--camera-size", "160x120", "--ideal"]
    assert main([*args, "--set", "bit_depth=16", "--out", str(out)]) == 0
    assert replay_session(str(out)).frame_dtype == np.uint16
    (out / read_dump(out).frames[0].file).write_bytes(b"not a png")
    assert replay_session(str(out)).frame_dtype == np.uint8  # (the replay camera reports that frame in its turn)
