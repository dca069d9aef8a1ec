"""`slscan decode --scheduler` on a real LocalCluster of 2 worker processes (started once for the module): the same
bytes as the local path, a worker killed mid-chunk, a rerun that resumes, and the one-line refusals.

The workers load the decoder's kernels from the NUMBA_CACHE_DIR this process uses (tests/conftest.py warms it before
the tests start, "Parallel runs"); they inherit it, and this checkout's sys.path, when LocalCluster spawns them.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed", reason="slscan[cluster] is not installed")

from app.cluster.client import MALLOC_TRIM_KEY  # noqa: E402
from app.dump import DumpWriter  # noqa: E402
from app.imageio import read_float_tiff  # noqa: E402
from app.patterns import two_shot_patterns  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
RUN_FILES = {"decode-run.yaml", ".decode-run"}  # what a cluster run adds to the local path's files


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of 2 single-threaded worker processes and a client on it, as `--scheduler local:2` makes it."""
    import dask

    with dask.config.set({MALLOC_TRIM_KEY: None}):
        lc = distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=50
        )
    with lc, distributed.Client(lc) as client:
        # the workers run this checkout's code, not an installed slscan
        where = client.run(lambda: __import__("app").__file__)
        assert all(Path(f).resolve().is_relative_to(ROOT) for f in where.values()), where
        yield client


@pytest.fixture(scope="module")
def rig():
    from drivers.sim.rig import VirtualRig

    return VirtualRig.from_preset("plane", camera_size=(320, 240), projector_size=(512, 384))


@pytest.fixture(scope="module")
def make_dump(rig, tmp_path_factory):
    """factory(name, frames) -> a two-shot dump of the plane (pattern tags alternate, starting with the inverse)."""
    ps = two_shot_patterns(rig.projector_size)
    images = [rig.render(ps.images[p]) for p in (0, 1)]
    root = tmp_path_factory.mktemp("dumps")

    def make(name: str, frames: int) -> Path:
        folder = root / name
        if not folder.exists():
            with DumpWriter(folder, ps, rig.calibration, rig.depth_range_mm) as w:
                for i in range(frames):
                    p = 1 - i % 2
                    w.add(images[p], p, 100 + i, 1000 * i)
        return folder

    return make


PAIRED = {"a": 9, "b": 6}  # dumps the local path decodes together, in one run of several dumps (OUT/<name>/)


@pytest.fixture(scope="module")
def local_out(make_dump, tmp_path_factory):
    """factory(name, frames) -> the local path's output folder of that dump (decoded once)."""
    done: dict[str, Path] = {}

    def get(name: str, frames: int) -> Path:
        if name not in done:
            out = tmp_path_factory.mktemp("local") / "out"
            names = list(PAIRED) if name in PAIRED else [name]
            dumps = [make_dump(n, PAIRED.get(n, frames)) for n in names]
            r = cli("decode", *dumps, "--out", out, "--workers", "1")
            assert r.returncode == 0, r.stderr
            done.update({n: out / n if len(names) > 1 else out for n in names})
        return done[name]

    return get


def cli(*args: object, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True, timeout=120, cwd=ROOT, **kw
    )


def assert_same_files(local: Path, cluster: Path) -> None:
    """Every file of the local path's output, byte for byte, and nothing else but the run's manifest and markers."""
    names = sorted(p.name for p in local.iterdir())
    assert sorted(p.name for p in cluster.iterdir() if p.name not in RUN_FILES) == names
    for name in names:
        assert (cluster / name).read_bytes() == (local / name).read_bytes(), name


def test_outputs_are_the_local_paths_bytes_for_several_dumps(cluster, make_dump, local_out, rig, tmp_path):
    a, b = make_dump("a", 9), make_dump("b", 6)
    out = tmp_path / "out"
    r = cli("decode", a, b, "--out", out, "--scheduler", cluster.scheduler.address, "--chunk-sets", "3")
    assert r.returncode == 0, r.stderr
    assert "decoded 8 of 8 two-shot frame set(s) from 9 frames" in r.stdout
    assert "13 frame set(s) decoded in 5 chunk(s) on 2 worker(s)" in r.stdout and "0 failed" in r.stdout
    assert r.stdout.count("  worker ") == 2, r.stdout  # throughput per worker
    assert r.stderr == "", r.stderr  # (no warning: the workers run without Dask's MALLOC_TRIM_THRESHOLD_)
    assert_same_files(local_out("a", 9), out / "a")  # (the local path decoded a and b in one run: OUT/a/, OUT/b/)
    assert_same_files(local_out("b", 6), out / "b")
    depth = read_float_tiff(out / "a" / "depth_000007.tiff")  # the last chunk's last set, against the truth
    ok = depth > 0
    assert ok.mean() > 0.9 and np.sqrt(np.mean((depth[ok] - rig.ground_truth.depth[ok]) ** 2)) < 1.0


def test_a_worker_killed_mid_chunk_has_its_chunk_decoded_elsewhere(cluster, make_dump, local_out, tmp_path):
    dump = make_dump("long", 19)
    out = tmp_path / "out"
    pids = set(cluster.run(os.getpid).values())
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "decode", str(dump), "--out", str(out), "--scheduler",
         cluster.scheduler.address, "--chunk-sets", "6"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    partial = out / ".decode-run" / "partial"
    killed = None
    deadline = time.monotonic() + 60
    while killed is None and proc.poll() is None and time.monotonic() < deadline:
        # a task's partial folder is named after its worker's pid: kill that worker while the chunk is being written
        for p in partial.iterdir() if partial.is_dir() else ():
            m = re.search(r"-p(\d+)-", p.name)
            if m and int(m.group(1)) in pids:
                killed = int(m.group(1))
                os.kill(killed, signal.SIGKILL)
                break
        time.sleep(0.002)
    stdout, stderr = proc.communicate(timeout=120)
    assert killed is not None, "no task started"
    assert proc.returncode == 0, stderr
    assert "18 frame set(s) decoded" in stdout and "0 failed" in stdout, stdout
    assert "1 task attempt(s) interrupted" in stdout, stdout  # the kill hit a chunk mid-way; it was decoded again
    assert_same_files(local_out("long", 19), out)
    assert not any(partial.iterdir())
    cluster.wait_for_workers(2, timeout=60)  # the nanny restarts the killed worker for the next tests


def test_a_rerun_skips_the_complete_chunks_and_redoes_the_rest(cluster, make_dump, local_out, tmp_path):
    dump = make_dump("a", 9)
    out = tmp_path / "out"
    args = ("decode", dump, "--out", out, "--scheduler", cluster.scheduler.address, "--chunk-sets", "3")
    assert cli(*args).returncode == 0
    kept = (out / "depth_000000.tiff").stat()  # chunk 0
    (out / "cloud_000004.ply").unlink()  # chunk 1 lost a file
    (out / ".decode-run" / "markers" / "_" / "chunk-000002.yaml").unlink()  # chunk 2 never finished
    r = cli(*args)
    assert r.returncode == 0, r.stderr
    assert "5 frame set(s) decoded in 2 chunk(s)" in r.stdout and "3 skipped (1 chunk(s) complete" in r.stdout
    assert (out / "depth_000000.tiff").stat().st_mtime_ns == kept.st_mtime_ns  # not written again
    assert_same_files(local_out("a", 9), out)
    # the same OUT with other options, or a folder that holds something else, is refused in one line
    r = cli(*args[:-1], "4")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "other options (chunk_sets)" in r.stderr
    r = cli("decode", dump, "--out", local_out("a", 9), "--scheduler", cluster.scheduler.address)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "holds no decode-run.yaml" in r.stderr


def test_a_scheduler_that_does_not_answer_is_one_line_and_writes_nothing(make_dump, tmp_path):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "out"
    address = f"tcp://127.0.0.1:{port}"
    r = cli("decode", make_dump("b", 6), "--out", out, "--scheduler", address, "--connect-timeout", "1")
    assert r.returncode == 2
    assert r.stderr == f"slscan decode: error: --scheduler {address}: no Dask scheduler answered within 1 s\n"
    assert not out.exists()


def test_without_the_extra_the_error_names_it(make_dump, tmp_path):
    code = "import sys; sys.modules['distributed'] = None; from app.cli import main; sys.exit(main(sys.argv[1:]))"
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-c", code, "decode", str(make_dump("b", 6)), "--out", str(out), "--scheduler", "local:2"],
        capture_output=True, text=True, timeout=60, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "pip install 'slscan[cluster]'" in r.stderr
    assert not out.exists()


def test_cluster_options_without_a_scheduler_are_refused(make_dump, tmp_path):
    r = cli("decode", make_dump("b", 6), "--out", tmp_path / "out", "--chunk-sets", "3")
    assert r.returncode == 2 and "go with --scheduler" in r.stderr and not (tmp_path / "out").exists()


def test_a_copy_of_a_dump_under_the_same_name_is_refused(make_dump, tmp_path):
    other = tmp_path / "x" / "a"
    shutil.copytree(make_dump("a", 9), other)
    r = cli("decode", make_dump("a", 9), other, "--out", tmp_path / "out", "--workers", "1")
    assert r.returncode == 2 and "a second dump named 'a'" in r.stderr and not (tmp_path / "out").exists()


def test_zarr_holds_the_local_paths_depth_maps_and_opens_lazily(cluster, make_dump, local_out, tmp_path):
    import xarray as xr  # (slscan[test]: a reader that did not write the store; slscan itself does not need it)

    from core.dump import read_dump

    dump = make_dump("a", 9)
    out = tmp_path / "out"
    r = cli("decode", dump, "--out", out, "--scheduler", cluster.scheduler.address, "--chunk-sets", "3", "--zarr")
    assert r.returncode == 0, r.stderr
    ds = xr.open_zarr(out / "depth.zarr")
    assert ds.depth.dims == ("set", "y", "x") and ds.depth.dtype == np.float32 and ds.depth.shape == (8, 240, 320)
    assert ds.depth.chunks == ((3, 3, 2), (240,), (320,))  # dask-backed: nothing read yet, one chunk a task
    local = local_out("a", 9)
    for n in range(8):
        assert np.array_equal(ds.depth[n].values, read_float_tiff(local / f"depth_{n:06d}.tiff")), n
    frames = read_dump(dump).frames
    newest = [frames[n + 1] for n in range(8)]  # sliding pairs: set n is frames n and n + 1, the newest n + 1
    assert list(ds.timestamp_ns.values) == [f.timestamp_ns for f in newest]
    assert list(ds.frame_id.values) == [f.frame_id for f in newest]


def test_a_chunk_that_fails_is_reported_with_its_reason_and_redone_by_a_rerun(cluster, make_dump, tmp_path):
    dump = tmp_path / "a"
    shutil.copytree(make_dump("a", 9), dump)
    frame = dump / "frames" / "000004.png"  # frame 4: sets 3 and 4, and set 5's previous frame: chunk 1 only
    good = frame.read_bytes()
    frame.write_bytes(good[: len(good) // 2])
    out = tmp_path / "out"
    args = ("decode", dump, "--out", out, "--scheduler", cluster.scheduler.address, "--chunk-sets", "3")
    r = cli(*args)
    assert r.returncode == 1, r.stderr
    assert "5 frame set(s) decoded in 2 chunk(s)" in r.stdout and "3 failed" in r.stdout, r.stdout
    assert re.search(rf"failed: {re.escape(str(dump))} chunk 1 \(sets 3-5\): .*000004\.png", r.stdout), r.stdout
    assert not (out / "depth_000003.tiff").exists()
    frame.write_bytes(good)
    r = cli(*args)
    assert r.returncode == 0, r.stderr
    assert "3 frame set(s) decoded in 1 chunk(s)" in r.stdout and "5 skipped (2 chunk(s)" in r.stdout, r.stdout
    local = tmp_path / "local"  # (of this copy of the dump: the sidecars name the folder the frames came from)
    assert cli("decode", dump, "--out", local, "--workers", "1").returncode == 0
    assert_same_files(local, out)
