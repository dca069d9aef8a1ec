"""Crash-safe recording: `slscan dump` kill -9'd at many random points, each time a readable dump.

Each kill is a real `slscan dump` process on the virtual rig (320x240), killed after a random
number of index entries plus a random fraction of a frame period (so some kills land inside a
PNG write or an index append). Every time: the dump reads back up to its last complete frame,
every listed frame loads, frame ids only go up, each frame's pixels are the pattern its tag names
(checked against the same rig's render of both patterns), and `slscan dump --repair` leaves an
index that lists those frames (and the one whose rename the kill prevented, recovered with its tag)
and nothing else in frames/ (strays go to orphans/, never deleted). (Disk-full while recording is covered in
tests/app/live/test_recording.py; the recorder-level kill loop there too: this one is the CLI.)
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from app.cli import main
from app.config import DEFAULT_CONFIG
from core.dump import read_dump

from .conftest import SMALL, fresh_devices

KILLS = 12
AT_ONCE = 4  # processes alive together (each spends most of its life starting up)


@pytest.fixture(scope="module")
def small_config(tmp_path_factory):
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["sim"].update(SMALL)
    path = tmp_path_factory.mktemp("cfg") / "small.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def textured_config(small_config):
    """small_config with a white-light texture frame every 7 frames (recorded with its tag)."""
    data = yaml.safe_load(small_config.read_text())
    data.setdefault("capture", {})["texture_every"] = 7
    path = small_config.with_name("textured.yaml")
    path.write_text(yaml.safe_dump(data))
    return path


def _entries(folder) -> int:
    try:
        return (folder / "dump.yaml").read_bytes().count(b"\n- {")
    except OSError:
        return 0


def _kill_runs(configs, tmp_path, rng) -> list:
    """Start KILLS `slscan dump` processes (AT_ONCE at a time, taking the configs in turn) and kill -9 each at its
    random point."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    todo = [
        (tmp_path / f"rec{k}", int(rng.integers(1, 60)), float(rng.uniform(0, 0.017)), configs[k % len(configs)])
        for k in range(KILLS)
    ]
    running: list = []
    done: list = []
    deadline = time.monotonic() + 150
    while (todo or running) and time.monotonic() < deadline:
        while todo and len(running) < AT_ONCE:
            folder, target, extra, config = todo.pop()
            cmd = [sys.executable, "-m", "app.cli", "dump", "--config", str(config), "--frames", "100000"]
            proc = subprocess.Popen(
                [*cmd, "--out", str(folder)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env
            )
            running.append((proc, folder, target, extra))
        for item in list(running):
            proc, folder, target, extra = item
            if _entries(folder) >= target or proc.poll() is not None:
                time.sleep(extra)
                proc.send_signal(signal.SIGKILL)
                proc.wait()
                running.remove(item)
                done.append((folder, target, proc.returncode))
        time.sleep(0.002)
    for proc, *_ in running:
        proc.kill()
        proc.wait()
    return done


@pytest.mark.slow  # 30-60 s on the shared 2-core machine: 12 real `slscan dump` processes
def test_kill_9_of_slscan_dump_at_random_points(small_config, textured_config, tmp_path, rig_session):
    session, _ = rig_session
    dev = fresh_devices(session)
    rig, prepared = dev.camera.bench.rig, dev.camera.bench.patterns  # (the patterns, then the white texture frame)
    refs = [rig.render(prepared[p]).astype(np.float32) for p in range(len(prepared))]
    done = _kill_runs([small_config, textured_config], tmp_path, np.random.default_rng(8))
    assert len(done) == KILLS
    textures = [len(read_dump(folder).texture_indices()) for folder, _, _ in done]
    assert sum(textures) >= 3, textures  # the textured half recorded texture frames (their pixels: checked below)
    for folder, target, code in done:
        assert code == -signal.SIGKILL, (folder, code)  # killed, not exited on its own
        dump = read_dump(folder)
        n = len(dump.frames)
        assert n >= target - 1, (folder, n, target)  # at most the entry being written is lost
        ids = [f.frame_id for f in dump.frames]
        assert ids == sorted(set(ids)), folder
        for i, rec in enumerate(dump.frames):
            img = dump.load_frame(i).astype(np.float32)
            assert img.shape == (240, 320, 3), (folder, rec.file)
            d = [float(np.mean(np.abs(img - r))) for r in refs]
            assert int(np.argmin(d)) == rec.pattern, (folder, rec, d)  # the pixels are the tagged pattern
        assert main(["dump", "--repair", str(folder)]) == 0  # the CLI repair
        again = read_dump(folder)
        # the frames as read, and at most the one whose rename the kill prevented (recovered with its tag)
        again_ids = [f.frame_id for f in again.frames]
        assert again_ids[: len(ids)] == ids and len(again_ids) - len(ids) <= 1 and again.dropped_tail == 0
        for i in range(len(ids), len(again.frames)):
            img = again.load_frame(i).astype(np.float32)
            d = [float(np.mean(np.abs(img - r))) for r in refs]
            assert int(np.argmin(d)) == again.frames[i].pattern, (folder, again.frames[i], d)
        assert not list((folder / "frames").glob("*.tmp*"))
        listed = {f.file.split("/")[-1] for f in again.frames}
        assert {p.name for p in (folder / "frames").iterdir()} == listed  # nothing unindexed left in frames/
        assert (folder / "dump.yaml").read_text().endswith("\n")


def test_disk_full_mid_session_stops_recording_and_the_session_goes_on(rig_session, tmp_path):
    """Frame files from the 10th on are the kernel's /dev/full (ENOSPC, as on a full disk): recording
    stops with a message and keeps its 10 frames; capture and decoding carry on."""
    from app.live_pipeline import LivePipeline
    from app.recorder import Recorder
    from core.dump import DumpWriter

    from .conftest import make_loop, mispaired

    session, processor = rig_session
    dev = fresh_devices(session)
    writer = DumpWriter(tmp_path / "rec", session.patterns, calibration=session.calibration)
    for i in range(10, 200):
        os.symlink("/dev/full", tmp_path / "rec" / "frames" / f"{i:06d}.tmp.png")
    rec = Recorder(writer)
    results = []
    pipe = LivePipeline(
        lambda: make_loop(session, dev), processor, max_frames=80, recorder=rec, on_result=results.append
    )
    pipe.start()
    pipe.wait()
    stats = rec.close()
    assert pipe.error is None and pipe.capture.frames == 80  # the session did not stop
    assert stats.written == 10 and "disk full" in rec.message and "10 frames" in rec.message, rec.message
    late = [r.frameset for r in results if min(r.frameset.frame_ids) > 40]
    assert late and mispaired(dev, late) == []  # decoding went on after the recording stopped
    dump = read_dump(tmp_path / "rec")
    assert len(dump.frames) == 10 and dump.dropped_tail == 0
    assert all(dev.camera.truth(f.frame_id) == f.pattern for f in dump.frames)
