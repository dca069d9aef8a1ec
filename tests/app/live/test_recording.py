"""Recording: a dump written live decodes with nothing else; kill -9 leaves a readable dump;
a full disk stops recording and keeps what was written; a dump replays through the pipeline."""

from __future__ import annotations

import itertools
import os
import re
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import yaml

from app.cli import main
from app.config import DEFAULT_CONFIG
from app.live_pipeline import LivePipeline
from app.recorder import Recorder
from app.session import build_session, open_recorder
from core.dump import DumpWriter, read_dump, repair_dump
from core.imageio import read_float_tiff
from core.patterns import two_shot_patterns
from drivers.base import Frame

from .conftest import SMALL, depth_agreement


def small_config(tmp_path, **sim) -> str:
    """config/sim.yaml at 320x240, with `sim:` keys replaced, as a file for the CLI."""
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["sim"].update(camera_size=[320, 240], **sim)
    path = tmp_path / "small.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def wait_for_frames(folder, n: int, timeout_s: float = 90.0, poll_s: float = 0.02) -> None:
    """Until the dump being written in `folder` lists n frames (or the timeout passes)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        idx = folder / "dump.yaml"
        if idx.is_file() and idx.read_text().count("\n- {") >= n:
            return
        time.sleep(poll_s)


def slscan_dump(start, cfg: str, out, **kw) -> subprocess.Popen:
    """`slscan dump` of up to 100,000 frames, started by the `slscan_process` fixture."""
    return start("dump", "--config", cfg, "--frames", "100000", "--out", out, **kw)


def record(session, folder, frames: int, png_level: int = 0):
    rec = open_recorder(session, folder, png_level)
    pipe = LivePipeline(lambda: session.make_loop(timeout_s=3.0), None, max_frames=frames, recorder=rec)
    pipe.start()
    pipe.wait()
    stats = rec.close()
    return pipe, rec, stats


def test_dump_written_live_decodes_with_nothing_else(tmp_path, sim_session, capsys):
    session = build_session(None, sim_overrides=SMALL)
    pipe, rec, stats = record(session, tmp_path / "rec", frames=24)
    assert pipe.error is None and rec.message is None
    # every frame whose tag is certain is in the dump (the pixel check confirms all but the first)
    assert stats.written == pipe.capture.confirmed >= pipe.capture.tagged - 2 and stats.lost == 0
    dump = read_dump(tmp_path / "rec")
    assert len(dump.frames) == stats.written
    # the tags in the dump are what the frames really saw
    assert all(session.sim.camera.truth(f.frame_id) == f.pattern for f in dump.frames)
    assert dump.calibration().camera_size == (320, 240)
    assert dump.depth_range_mm() == tuple(map(float, session.sim.rig.depth_range_mm))  # the scene's volume
    assert main(["decode", str(tmp_path / "rec"), "--out", str(tmp_path / "out")]) == 0
    depth = read_float_tiff(tmp_path / "out" / "depth_000000.tiff")
    correct, coverage = depth_agreement(depth, session.sim.rig.ground_truth)
    assert correct > 0.95 and coverage > 0.25


def test_replay_runs_a_dump_through_the_live_pipeline(tmp_path, sim_session):
    from app.commands.replay import replay_session

    session, processor = sim_session
    record(build_session(None, sim_overrides=SMALL), tmp_path / "rec", frames=16)
    replay = replay_session(str(tmp_path / "rec"))
    results = []
    pipe = LivePipeline(lambda: replay.make_loop(), processor, on_result=results.append, max_frames=10**9)
    pipe.start()
    pipe.wait()
    assert pipe.error is None  # the end of the dump is a normal end
    n = len(read_dump(tmp_path / "rec").frames)
    assert pipe.capture.frames == n and pipe.capture.refused == 0
    assert pipe.stats.decoded >= 1
    correct, _ = depth_agreement(pipe.latest.depth, session.sim.rig.ground_truth)
    assert correct > 0.95


def test_full_disk_stops_recording_and_keeps_what_was_written(tmp_path):
    writer = DumpWriter(tmp_path / "rec", two_shot_patterns((64, 48)))
    rec = Recorder(writer)
    rng = np.random.default_rng(1)
    frames = [Frame(rng.integers(0, 255, (24, 32, 3), np.uint8), i + 1, 1000 * i, pattern=i % 2) for i in range(8)]
    for f in frames[:3]:
        rec.put(f)
    while rec.stats.written < 3:
        time.sleep(0.01)
    # the next frame's file is the kernel's /dev/full: writing it fails with ENOSPC, as on a full disk
    os.symlink("/dev/full", tmp_path / "rec" / "frames" / "000003.tmp.png")
    for f in frames[3:]:
        rec.put(f)
    stats = rec.close()
    assert stats.written == 3 and stats.not_written == 5
    assert "disk full" in rec.message and "keeps the 3 frames" in rec.message
    assert "5 frame(s) NOT recorded" in rec.summary()
    dump = read_dump(tmp_path / "rec")
    assert len(dump.frames) == 3
    assert all(np.array_equal(dump.load_frame(i), frames[i].image) for i in range(3))


RECORDER_SCRIPT = textwrap.dedent(
    """
    import sys, numpy as np
    from core.dump import DumpWriter
    from core.patterns import two_shot_patterns
    from app.recorder import Recorder
    from drivers.base import Frame
    rec = Recorder(DumpWriter(sys.argv[1], two_shot_patterns((64, 48)), png_level=int(sys.argv[2])))
    rng = np.random.default_rng(0)
    i = 0
    while True:
        while not rec.put(Frame(rng.integers(0, 255, (120, 160, 3), np.uint8), i + 1, 1000 * i, pattern=i % 2)):
            pass
        i += 1
    """
)


@pytest.mark.parametrize("png_level", [0, 1])
def test_kill_9_at_random_points_leaves_a_readable_dump(tmp_path, png_level):
    rng = np.random.default_rng(png_level)
    for k in range(3):
        folder = tmp_path / f"rec{k}"
        proc = subprocess.Popen([sys.executable, "-c", RECORDER_SCRIPT, str(folder), str(png_level)])
        try:
            wait_for_frames(folder, 3, timeout_s=60, poll_s=0.01)
            time.sleep(float(rng.uniform(0, 0.3)))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
        dump = read_dump(folder)
        assert len(dump.frames) >= 3
        assert [f.frame_id for f in dump.frames] == list(range(1, len(dump.frames) + 1))
        for i in range(len(dump.frames)):
            assert dump.load_frame(i).shape == (120, 160, 3)
        report = repair_dump(folder)
        # (a kill between a frame's index entry and its rename leaves it complete: repair renames it into place)
        assert report.frames == len(dump.frames) + report.recovered and report.recovered <= 1
        assert not list((folder / "frames").glob("*.tmp.png"))
        again = read_dump(folder)
        assert len(again.frames) == report.frames and again.dropped_tail == 0
        for i in range(len(again.frames)):
            assert again.load_frame(i).shape == (120, 160, 3)
        assert (folder / "dump.yaml").read_text().endswith("\n")


def test_kill_9_of_slscan_dump_leaves_a_readable_dump(tmp_path, slscan_process):
    out = tmp_path / "rec"
    proc = slscan_dump(
        slscan_process, small_config(tmp_path), out, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        wait_for_frames(out, 6)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    dump = read_dump(out)
    assert len(dump.frames) >= 6
    for i in range(len(dump.frames)):
        assert dump.load_frame(i).shape == (240, 320, 3)
    assert dump.calibration() is not None


def test_camera_that_stops_sending_times_out_and_the_dump_is_finalised(tmp_path, capsys):
    cfg = small_config(tmp_path, faults=[{"kind": "stall", "at": [12], "seconds": 1.5}])
    out = tmp_path / "rec"
    code = main(["dump", "--config", cfg, "--frames", "1000", "--out", str(out), "--timeout", "0.5"])
    err = capsys.readouterr().err
    assert code == 2
    assert "no frame within" in err and "finalised" in err
    dump = read_dump(out)
    assert 5 <= len(dump.frames) <= 11 and dump.dropped_tail == 0
    assert (out / "dump.yaml").read_text().endswith("\n")


@pytest.mark.parametrize(
    ("sig", "code", "said"), [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")]
)
def test_ctrl_c_or_sigterm_stops_slscan_dump_cleanly_with_its_summary(tmp_path, slscan_process, sig, code, said):
    out = tmp_path / "rec"
    proc = slscan_dump(
        slscan_process, small_config(tmp_path), out, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    wait_for_frames(out, 4)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == code, stderr
    assert f"{said}; the dump is finalised" in stderr and "Traceback" not in stderr
    assert "recorded" in stdout and "NOT recorded" not in stdout
    dump = read_dump(out)
    assert len(dump.frames) >= 4 and dump.dropped_tail == 0
    assert not list((out / "frames").glob("*.tmp.png"))


@pytest.mark.parametrize("frames", [2, 20])
def test_slscan_dump_frames_n_records_n_frames_past_refused_ones(tmp_path, capsys, frames):
    """A duplicated frame is refused (never recorded): capture goes on until N frames are recorded."""
    out = tmp_path / "rec"
    cfg = small_config(tmp_path, faults=[{"kind": "duplicate", "at": [3, 9]}])
    code = main(["dump", "--config", cfg, "--frames", str(frames), "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    dump = read_dump(out)
    assert len(dump.frames) == frames
    ids = [f.frame_id for f in dump.frames]
    assert ids == sorted(set(ids))
    if frames == 20:
        # the fault was seen and refused (a loaded machine's late frames may add refusals of their own: a bound on
        # the count would test the machine), and no recorded frame repeats the image before it
        refused = re.search(r"refused (\d+)", captured.out)
        assert refused is not None and int(refused.group(1)) >= 1, captured.out
        images = [dump.load_frame(i) for i in range(len(dump.frames))]
        assert not any(np.array_equal(a, b) for a, b in itertools.pairwise(images))


@pytest.fixture
def small_disk(tmp_path):
    """mount(size_mb): a tmpfs of that size (a disk that fills within a few seconds); skipped where mounting is
    not allowed."""
    mounted = []

    def mount(size_mb: int):
        mnt = tmp_path / f"disk{len(mounted)}"
        mnt.mkdir()
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_mb}m", "tmpfs", str(mnt)], capture_output=True)
        if r.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode().strip()}")
        mounted.append(mnt)
        return mnt

    try:
        yield mount
    finally:
        for mnt in mounted:
            subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def test_live_recording_into_a_full_disk_is_no_success(tmp_path, capsys, small_disk):
    # room to start (3 s of 320x240 frames at 60 Hz: 41 MB), not for the whole recording (5 s)
    disk = small_disk(48)
    cfg = small_config(tmp_path)
    out, rec = str(tmp_path / "out"), str(disk / "rec")
    code = main(["live", "--headless", "--config", cfg, "--frames", "300", "--out", out, "--record", rec])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "NOT recorded" in err and "Traceback" not in err
    dump = read_dump(disk / "rec")  # what fitted is kept, readable
    assert 150 <= len(dump.frames) < 300


def test_a_recording_without_room_to_start_is_refused_before_the_session(tmp_path, capsys, small_disk):
    disk = small_disk(3)
    cfg = small_config(tmp_path)
    out, rec = tmp_path / "out", disk / "rec"
    code = main(["live", "--headless", "--config", cfg, "--frames", "60", "--out", str(out), "--record", str(rec)])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert str(rec) in err[0] and "MB needed to start" in err[0]
    assert "frames in" not in captured.out  # no session ran
    assert not rec.exists() and not out.exists()


@pytest.mark.parametrize("target", ["/dev/full", "/dev/null"])
def test_a_scan_folder_that_is_a_device_is_refused_before_the_session(tmp_path, capsys, target):
    code = main(["live", "--headless", "--config", small_config(tmp_path), "--frames", "10", "--out", target])
    captured = capsys.readouterr()
    assert code == 2 and captured.err.strip() == f"slscan live: error: {target}: exists and is not a folder"
    assert "frames in" not in captured.out
