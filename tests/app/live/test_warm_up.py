"""The session's decoder is compiled (or loaded from numba's cache) before frames arrive, and a slow first
compile is announced: a cold `slscan live` had spent its first 69 s compiling in the decode thread, holding the
GIL, with no depth maps and no word to the operator."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time

import numpy as np

from app.live_pipeline import LiveDecoder
from app.session import build_session

from .conftest import SMALL


def _record(monkeypatch, name: str, delay_s: float = 0.0) -> list:
    """The arguments of every call of LiveDecoder.<name> (after delay_s, then the real method)."""
    seen: list = []
    real = getattr(LiveDecoder, name)

    def spy(self, *args, **kw):
        seen.append((args, kw))
        time.sleep(delay_s)
        return real(self, *args, **kw)

    monkeypatch.setattr(LiveDecoder, name, spy)
    return seen


def test_session_processor_decodes_a_blank_set_of_the_camera_size_and_dtype_first(monkeypatch):
    warmed = _record(monkeypatch, "warm_up")
    decoded = _record(monkeypatch, "decode_depth")
    session = build_session(None, sim_overrides={**SMALL, "bit_depth": 16})
    session.processor()
    assert len(warmed) == 1
    (dtype,), kw = warmed[0]
    assert dtype == np.uint16 and kw["announce"] == session._announce_compile
    ((images, newest, previous), _), *_ = decoded
    assert [(im.shape, im.dtype) for im in images] == [((240, 320, 3), np.dtype(np.uint16))] * 2
    assert not any(im.any() for im in images)
    # and with the frame before the pair, so that the motion repair compiles too
    assert newest == 1 and previous.shape == (240, 320, 3) and previous.dtype == np.uint16 and not previous.any()


def test_a_slow_warm_up_is_announced_once_and_a_fast_one_is_not(monkeypatch, sim_session):
    processor = sim_session[1]
    calls: list[float] = []
    # fast (compiled already): the timer is cancelled, nothing said even once its time has passed
    assert processor.warm_up(np.uint8, announce=lambda: calls.append(time.perf_counter()), after_s=0.3) < 0.3
    time.sleep(0.6)
    assert calls == []
    _record(monkeypatch, "decode_depth", delay_s=0.4)
    t0 = time.perf_counter()
    took = processor.warm_up(np.uint8, announce=lambda: calls.append(time.perf_counter()), after_s=0.05)
    time.sleep(0.1)
    assert took >= 0.4 and len(calls) == 1 and calls[0] - t0 < 0.4


def test_the_announcement_names_the_scheme_on_stderr(capsys, sim_session):
    sim_session[0]._announce_compile()
    err = capsys.readouterr().err
    assert "compiling the two-shot decoder" in err and "about a minute" in err


# In a fresh process (numba's dispatchers start empty): after the warm-up, decoding the rig's frames must add
# no kernel signature, i.e. compile (or load) nothing more.
NOTHING_NEW = textwrap.dedent(
    """
    import sys, numba
    from app.session import build_session

    def signatures():
        out = {}
        for name, mod in list(sys.modules.items()):
            if name.startswith(("app.", "drivers.")):
                for attr, obj in vars(mod).items():
                    if isinstance(obj, numba.core.registry.CPUDispatcher):
                        out[f"{name}.{attr}"] = set(obj.signatures)
        return out

    session = build_session(None, scheme=sys.argv[1], sim_overrides={"camera_size": [320, 240]})
    processor = session.processor()
    before = signatures()
    frames = [session.sim.rig.render(im) for im in session.patterns.images]
    _, depth, _ = processor.decode_depth(tuple(frames))
    if len(frames) == 2:  # a sliding pair with the frame before it (motion handling)
        previous = session.sim.rig.render(session.patterns.images[1])
        processor.decode_depth(tuple(frames), 1, previous)
    after = signatures()
    print("warmed kernels", sum(bool(s) for s in before.values()))
    print("new", sorted(k for k, s in after.items() if s - before.get(k, set())))
    print("depth", float((depth > 0).mean()))
    """
)


def test_after_the_warm_up_the_first_frames_compile_nothing():
    r = subprocess.run(
        [sys.executable, "-c", NOTHING_NEW, "two-shot"], capture_output=True, text=True, timeout=600, env=os.environ
    )
    assert r.returncode == 0, r.stderr[-2000:]
    lines = dict(line.split(" ", 1) for line in r.stdout.splitlines())
    assert int(lines["warmed"].split()[-1]) >= 3, r.stdout
    assert lines["new"] == "[]", r.stdout
    assert float(lines["depth"]) > 0.3, r.stdout


def test_a_replay_warms_up_for_its_dumps_frames_and_survives_an_unreadable_first_frame(tmp_path):
    from app.cli import main
    from app.commands.replay import replay_session
    from core.dump import read_dump

    out = tmp_path / "d16"
    args = ["sim", "render", "--scene", "plane", "--scheme", "two-shot", "--camera-size", "160x120", "--ideal"]
    assert main([*args, "--set", "bit_depth=16", "--out", str(out)]) == 0
    assert replay_session(str(out)).frame_dtype == np.uint16
    (out / read_dump(out).frames[0].file).write_bytes(b"not a png")
    assert replay_session(str(out)).frame_dtype == np.uint8  # (the replay camera reports that frame in its turn)
