"""`slscan live --publish` and slscan.Subscriber: a subscriber process gets the session's scans; a stalled one
costs the session nothing; a bad address is one line before the session starts."""

from __future__ import annotations

import re
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

import slscan
from app.cli import main
from app.config import DEFAULT_CONFIG
from core.depth_message import calibration_digest
from core.imageio import read_float_tiff

from .conftest import ROOT

zmq = pytest.importorskip("zmq")
SCRIPT = ROOT / "tests" / "slscan" / "stream_subscriber.py"
pytestmark = pytest.mark.xdist_group("live-stream")  # two live sessions at once would skew the rates


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def sim_session_small():
    """A 320x240 virtual-rig session and its decoder, for the in-process tests."""
    from app.session import build_session

    session = build_session(None, sim_overrides={"camera_size": [320, 240]})
    return session, session.processor()


@pytest.fixture(scope="module")
def small_config(tmp_path_factory) -> str:
    """The virtual rig at 320x240."""
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["sim"]["camera_size"] = [320, 240]
    path = tmp_path_factory.mktemp("stream") / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def start_subscriber(address: str, out, stall_s: float = 0.0, points: bool = False) -> subprocess.Popen:
    args = [sys.executable, str(SCRIPT), address, str(out), str(stall_s)] + (["points"] if points else [])
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready", proc.stderr.read()
    return proc


def live(config: str, frames: int, out, *extra: str) -> tuple[subprocess.CompletedProcess, dict]:
    cmd = [sys.executable, "-m", "app.cli", "live", "--headless", "--config", config, "--frames", str(frames)]
    res = subprocess.run([*cmd, "--out", str(out), *extra], capture_output=True, text=True, timeout=50, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    m = re.search(r"frames in: (\d+) \(([\d.]+)/s\)\s+depth maps out: (\d+) \(([\d.]+)/s\)", res.stdout)
    assert m, res.stdout
    fig = {"frames": int(m[1]), "frames_per_s": float(m[2]), "depth_maps": int(m[3]), "depth_per_s": float(m[4])}
    pub = re.search(r"published (\d+) scan\(s\) to \S+ \((\d+) dropped here", res.stdout)
    if pub:
        fig["published"], fig["dropped_here"] = int(pub[1]), int(pub[2])
    return res, fig


def test_a_subscriber_process_receives_every_scan_of_a_live_session(tmp_path, small_config):
    address = f"tcp://127.0.0.1:{free_port()}"
    sub = start_subscriber(address, tmp_path / "got.npz", points=True)
    # one decode worker: with two, a set that finishes after a newer one is dropped (stale), and counted
    res, fig = live(small_config, 120, tmp_path / "out", "--workers", "1", "--publish", address, "--publish-points")
    assert sub.wait(timeout=30) == 0, sub.stderr.read()
    got = np.load(tmp_path / "got.npz")
    rows = got["rows"]
    # nothing missing at the camera's 60 Hz: every depth map the session made, in order, none dropped
    assert fig["published"] == fig["depth_maps"] >= 50 and fig["dropped_here"] == 0
    assert len(rows) == fig["published"] and int(got["missed"]) == 0 and bool(got["ended"])
    assert np.array_equal(rows[:, 0], np.arange(len(rows)))  # sequence numbers without a gap
    assert np.all(np.diff(rows[:, 1]) > 0)  # the newest frame id of each scan increasing
    assert np.all(rows[:, 3] == 0)
    # the last scan received is the one the session saved, bit for bit (the frames it names are the same)
    m = re.search(r"last scan \(frames (\d+), (\d+)\)", res.stdout)
    assert {int(rows[-1, 1]), int(rows[-1, 2])} == {int(m[1]), int(m[2])}
    saved = read_float_tiff(tmp_path / "out" / "depth.tiff")
    assert saved.shape == (240, 320) and np.array_equal(got["depth"], saved)
    assert (saved > 0).mean() > 0.25
    session_cal = slscan.Scanner(small_config).calibration
    assert str(got["digest"]) == calibration_digest(session_cal)


def test_a_stalled_subscriber_does_not_slow_the_session_and_sees_its_losses(tmp_path, small_config):
    frames = 300  # 5 s at 60 Hz; the subscriber reads nothing for 3 s after the first scan
    _, alone = live(small_config, frames, tmp_path / "alone")
    address = f"tcp://127.0.0.1:{free_port()}"
    sub = start_subscriber(address, tmp_path / "got.npz", stall_s=3.0)
    t0 = time.monotonic()
    _, watched = live(small_config, frames, tmp_path / "watched", "--publish", address)
    assert sub.wait(timeout=40) == 0, sub.stderr.read()
    print(f"alone {alone}, with a stalled subscriber {watched} ({time.monotonic() - t0:.1f} s)")
    assert watched["frames_per_s"] >= 0.95 * alone["frames_per_s"]
    assert watched["depth_per_s"] >= 0.9 * alone["depth_per_s"]
    got = np.load(tmp_path / "got.npz")
    seq = got["rows"][:, 0]
    # PUB dropped what the stalled subscriber's pipe could not hold: it sees the gap, and the rest arrived (the
    # sequence numbers count every scan offered: those the session itself dropped are gaps too)
    offered = watched["published"] + watched["dropped_here"]
    assert int(got["missed"]) > 0 and len(seq) + int(got["missed"]) == offered
    assert np.all(np.diff(seq) > 0) and bool(got["ended"])


@pytest.mark.parametrize(
    ("address", "expected"),
    [
        ("127.0.0.1:5556", "expected tcp://HOST:PORT"),
        ("tcp://127.0.0.1", "expected tcp://HOST:PORT"),
        ("tcp://127.0.0.1:99999", "outside 1..65535"),
        ("udp://127.0.0.1:5556", "expected tcp://HOST:PORT"),
    ],
)
@pytest.mark.parametrize("command", ["live", "replay"])
def test_a_malformed_address_is_one_line_before_the_session(tmp_path, capsys, command, address, expected):
    args = ["live", "--headless"] if command == "live" else ["replay", str(tmp_path / "no-dump"), "--headless"]
    t0 = time.monotonic()
    assert main([*args, "--frames", "5", "--out", str(tmp_path / "out"), "--publish", address]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--publish {address}" in err and expected in err, err
    assert time.monotonic() - t0 < 2.0 and not (tmp_path / "out").exists()  # (no session was built)


def test_a_port_in_use_is_one_line_naming_the_address(tmp_path, capsys):
    ctx = zmq.Context()
    taken = ctx.socket(zmq.PUB)
    port = taken.bind_to_random_port("tcp://127.0.0.1")
    try:
        address = f"tcp://127.0.0.1:{port}"
        assert main(["live", "--headless", "--frames", "5", "--out", str(tmp_path / "o"), "--publish", address]) == 2
        err = capsys.readouterr().err
        assert err == f"slscan live: error: --publish {address}: cannot bind: the port is in use\n"
    finally:
        taken.close(0)
        ctx.term()


def test_publish_points_needs_publish_and_a_subscriber_needs_an_address(capsys):
    assert main(["live", "--headless", "--frames", "5", "--publish-points"]) == 2
    assert "--publish-points: needs --publish" in capsys.readouterr().err
    for bad in ("localhost:5556", "tcp://*:5556"):
        with pytest.raises(slscan.InputError, match=re.escape(f"slscan.Subscriber {bad}: expected tcp://HOST:PORT")):
            slscan.Subscriber(bad)


def test_a_subscriber_times_out_without_a_publisher():
    with slscan.Subscriber(f"tcp://127.0.0.1:{free_port()}", timeout_s=0.2) as sub:
        t0 = time.monotonic()
        assert list(sub) == [] and sub.receive(0.05) is None
        assert time.monotonic() - t0 < 2.0


def test_a_replay_publishes_its_scans_too(tmp_path, plane_dump):
    address = f"tcp://127.0.0.1:{free_port()}"
    sub = start_subscriber(address, tmp_path / "got.npz")
    cmd = [sys.executable, "-m", "app.cli", "replay", str(plane_dump), "--headless", "--workers", "1"]
    res = subprocess.run(
        [*cmd, "--out", str(tmp_path / "out"), "--publish", address], capture_output=True, text=True, timeout=50
    )
    assert res.returncode == 0, res.stderr
    assert sub.wait(timeout=30) == 0, sub.stderr.read()
    got = np.load(tmp_path / "got.npz")
    made = int(re.search(r"depth maps out: (\d+)", res.stdout)[1])  # (as fast as it decodes: some sets are stale)
    assert made >= 1 and f"published {made} scan(s)" in res.stdout
    assert len(got["rows"]) == made and bool(got["ended"])
    assert np.array_equal(got["depth"], read_float_tiff(tmp_path / "out" / "depth.tiff"))


def test_one_publisher_serves_pipelines_one_after_another(sim_session_small):
    """The view's scheme switch: a new LivePipeline (set indices from 0 again) on the same publisher; in-process,
    the subscriber reading on its own thread."""
    import threading

    from app.live_pipeline import LivePipeline
    from app.publisher import DepthPublisher

    session, processor = sim_session_small
    address = f"tcp://127.0.0.1:{free_port()}"
    publisher = DepthPublisher(address)
    made = 0
    sequences: list[int] = []
    with slscan.Subscriber(address, timeout_s=10.0) as sub:
        reader = threading.Thread(target=lambda: sequences.extend(scan.sequence for scan in sub))
        reader.start()
        time.sleep(0.3)  # connected before the first scan (PUB sends nothing to a subscriber not yet there)
        for _ in range(2):
            publisher.attach(processor)
            pipe = LivePipeline(
                lambda: session.make_loop(timeout_s=3.0), processor, max_frames=30, on_result=publisher.offer
            )
            pipe.start()
            pipe.wait()
            made += pipe.stats.decoded
        publisher.close()
        reader.join(15.0)
    assert publisher.dropped == 0 and made >= 40
    assert sequences == list(range(made)) and sub.ended and sub.missed == 0
