"""Shared test helpers. Each area keeps its own fixtures in its own tests/<area>/conftest.py.

The one X server: `xserver` is a session-wide Xvfb (1024x768, depth 24) for every test that opens a
window (projector, operator view, calibration wizard). `start_x_server` starts another server (the
two-monitor Xorg of the projector tests) the same way. Fixtures, not imports: the suite runs with
--import-mode=importlib.

Parallel runs (pytest-xdist, `.ci/run` uses `-n 2 --dist loadgroup`): see "Parallel runs" below.
"""

from __future__ import annotations

import glob
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator

import pytest

from core.jit_cache import cache_base  # (not core.jit: importing it fixes numba's cache folder)

XVFB_SIZE = (1024, 768)  # the projector tests' fullscreen window is this size


def _start_x_server(argv: list[str]) -> tuple[subprocess.Popen, str]:
    """Start an X server with `-displayfd`; returns it and its display name once it accepts clients.

    The server picks a free display number itself, so parallel sessions never collide.
    """
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        [argv[0], "-displayfd", str(write_fd), *argv[1:]],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    os.close(write_fd)
    number = b""
    deadline = time.monotonic() + 20
    with os.fdopen(read_fd, "rb") as pipe:
        # The server writes "N\n" once it accepts connections, or closes the pipe if it dies.
        while not number.endswith(b"\n") and time.monotonic() < deadline:
            chunk = pipe.read(1)
            if not chunk:
                break
            number += chunk
    if not number.strip().isdigit():
        proc.kill()
        err = proc.communicate(timeout=5)[1].decode(errors="replace")
        raise RuntimeError(f"{argv[0]} did not start: {err.strip()[-500:]}")
    return proc, f":{int(number)}"


def _stop_x_server(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@pytest.fixture(scope="session")
def start_x_server() -> Iterator[Callable[[list[str]], str]]:
    """start(argv) -> display name of a new X server, stopped at the end of the session."""
    procs: list[subprocess.Popen] = []

    def start(argv: list[str]) -> str:
        proc, name = _start_x_server(argv)
        procs.append(proc)
        return name

    try:
        yield start
    finally:
        for proc in procs:
            _stop_x_server(proc)


@pytest.fixture(scope="session")
def xserver(start_x_server: Callable[[list[str]], str]) -> str:
    """The display name (":N") of the session's Xvfb, 1024x768 depth 24 (at 16 pixels are not exact)."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (.ci/run installs it: apt-get install xvfb)")
    w, h = XVFB_SIZE
    return start_x_server(["Xvfb", "-screen", "0", f"{w}x{h}x24", "-nolisten", "tcp", "-nocursor"])


@pytest.fixture
def run_cli():
    """Run `slscan ARGS...` in a subprocess; returns CompletedProcess (text, captured)."""

    def run(*args: str, timeout: float = 120, **kw) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "app.cli", *map(str, args)], capture_output=True, text=True, timeout=timeout, **kw
        )

    return run


def _as_from_a_terminal() -> None:
    # A command started in the background of a non-interactive shell (`pytest ... &`, CI runners, xdist workers
    # started that way) inherits SIGINT ignored, and Python then installs no KeyboardInterrupt handler: the
    # child would never see the test's Ctrl-C. An operator's terminal runs slscan with SIGINT at its default.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


@pytest.fixture
def slscan_process() -> Iterator[Callable[..., subprocess.Popen]]:
    """Start `slscan ARGS...` as from an operator's terminal (Ctrl-C reaches it); killed at teardown if alive."""
    started: list[subprocess.Popen] = []

    def start(*args: str, **kw) -> subprocess.Popen:
        proc = subprocess.Popen(
            [sys.executable, "-m", "app.cli", *map(str, args)], preexec_fn=_as_from_a_terminal, **kw
        )
        started.append(proc)
        return proc

    yield start
    for proc in started:
        if proc.poll() is None:  # a failed test must not leave a recorder running after the suite
            proc.kill()
            proc.communicate()


# ----------------------------------------------------------------------------------------------- parallel runs
#
# `.ci/run` runs the suite on both cores with pytest-xdist, `-n 2 --dist loadgroup`. What that needs, all here:
#
# - The unit of work is a test file: all tests of a file run in one worker, in their order (module and session
#   fixtures are built as in a serial run). The files of one SAME_WORKER group run one after the other in one
#   worker, and so do tests marked `@pytest.mark.xdist_group("name")`, whatever their files. The slowest files
#   start first (SLOW_FIRST), so that no long file starts last while the other worker has nothing left to do.
# - numba's kernels. The two-shot decoder's cold compiles (uint8 and uint16 frames, a minute or two of each core)
#   are done once, before the workers start (pytest_xdist_setupnodes, WARM_UPS), into NUMBA_CACHE_DIR. Each worker
#   then caches into a folder of its own,
#   <NUMBA_CACHE_DIR>/xdist-<worker>, seeded with a copy of those kernels; the slscan processes its tests start
#   inherit it. numba writes a function's cache index and its compiled code as two files, so two processes that
#   compile different signatures of one function at once can leave an index entry naming the other's code
#   (numba/numba#10128: segfaults); within one worker, as in a serial run, kernels compile one at a time.
# - Progress: xdist alone prints one dot per test with no file names. Instead: one line per test file when its
#   last test is done (tests passed/failed/skipped, the worker, the file's wall time, the running count), and a
#   line at once for each failure. `-v` gives xdist's own line per test instead.

SLOW_FIRST = (
    # the test files that take longest (one core, the warm-up's cache), longest first; the others follow in
    # collection order. Only the order in which the workers take them: a stale entry costs time, not results.
    "tests/calibration/test_rig_source.py",
    "tests/calibration/test_wizard_window.py",
    "tests/app/cluster/test_cluster_decode.py",
    "tests/app/decode/test_simd.py",
    "tests/calibration/test_cli.py",
    "tests/app/decode/test_reference_full.py",
    "tests/app/decode/test_golden.py",
    "tests/app/decode/test_motion.py",
    "tests/reliability/test_crash_recording.py",
    "tests/app/decode/test_cli_decode.py",
    "tests/app/test_cli_patterns.py",
    "tests/reliability/test_bad_input_sweep.py",
    "tests/reliability/test_faults.py",
    "tests/app/live/test_real_rig_window.py",
    "tests/app/live/test_recording.py",
    "tests/drivers/projector/test_project_cli.py",
)


SAME_WORKER = {
    # The calibration tests that film the virtual rig in real time (20-30 Hz, rendering each frame as it is
    # grabbed): each needs most of a core, and short of it the simulated camera drops frames, so a take is
    # refused for the drops before its injected fault is seen (test_a_faulty_frame_makes_the_pose_be_retaken).
    # One at a time, never beside each other.
    "tests/calibration/test_rig_source.py": "calibration-rig",
    "tests/calibration/test_wizard_window.py": "calibration-rig",
}


# What the warm-up compiles, one process per entry, at once (each into a folder of its own, merged afterwards): the
# live two-shot decoder at uint8, as the sim_session/rig_session fixtures build it, which is also what `slscan
# live/dump/decode` and the golden two-shot cases run (with the virtual rig's kernels); and the same at uint16 (the
# 16-bit golden, reference and motion-repair cases, the warm-up's own test), which would otherwise compile in each
# worker that meets one.
WARM_UPS = {
    "uint8": """
from app.session import build_session
build_session(None, sim_overrides={"camera_size": [320, 240]}).processor()
""",
    "uint16": """
from app.session import build_session
build_session(None, sim_overrides={"camera_size": [320, 240], "bit_depth": 16}).processor()
""",
}


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_setupnodes(config: pytest.Config, specs) -> None:
    """Before the workers start: compile the two-shot decoder once into NUMBA_CACHE_DIR (each worker copies it).

    On an empty cache that takes one to two minutes of each core; paid here, no test's time includes it, and the
    workers do not both compile it. On a warm cache it is a few seconds of loading.
    """
    from core.jit_cache import merge_cache_folder, source_digest

    tr = config.pluginmanager.get_plugin("terminalreporter")
    base = cache_base()
    keyed = f"slscan-{source_digest()}"  # the folder core.jit compiles into for these sources
    t0 = time.monotonic()
    runs = []
    for name, script in WARM_UPS.items():
        folder = base / f"warm-up-{name}"
        if folder.exists():  # (a previous run's: merged already, and would be merged again)
            shutil.rmtree(folder)
        if (base / keyed).exists():  # a warm cache: each warm-up loads what is there rather than compile it again
            merge_cache_folder(base / keyed, folder / keyed)
        run = subprocess.Popen(
            [sys.executable, "-c", script],
            cwd=config.rootpath,
            env={**os.environ, "NUMBA_CACHE_DIR": str(folder)},
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        runs.append((name, folder, run))
    said = []
    for name, folder, run in runs:
        try:
            err = run.communicate(timeout=900)[1]
        except subprocess.TimeoutExpired:
            run.kill()
            err = run.communicate()[1] + "\ntimed out after 900 s"
        if run.returncode != 0:  # the tests that decode will fail and say why; the run goes on
            tail = err.strip().splitlines()[-1:] or ["no output"]
            said.append(f"{name} failed (exit {run.returncode}): {tail[0]}")
        else:
            said.append(f"{name} {'compiled' if 'compiling' in err else 'loaded'}")
        if folder.exists():
            merge_cache_folder(folder, base)
            shutil.rmtree(folder)
    if tr is not None:
        took = time.monotonic() - t0
        tr.write_line(f"numba warm-up: the two-shot decoder {', '.join(said)} into {base} in {took:.1f} s")


def _numba_cache_per_worker() -> None:
    """In an xdist worker: NUMBA_CACHE_DIR (core.jit's cache base) becomes <base>/xdist-<worker>, seeded with the
    kernels the warm-up compiled into <base>. A function's kernels are copied only where the worker has none: files
    copied whole, no index read (core.jit_cache.merge_cache_folder unpickles the indexes' signature keys, which
    creates numba's CPU target, before core.jit has set its vector width)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if not worker:
        return
    if "core.jit" in sys.modules:  # core.jit reads NUMBA_CACHE_DIR when imported
        raise RuntimeError("tests/conftest.py: core.jit was imported before the numba cache was set per worker")
    base = cache_base()
    own = base / f"xdist-{worker}"
    for index in base.glob("slscan-*/*/*.nbi"):  # <base>/slscan-<digest>/<source folder>/<module.function>.nbi
        folder = own / index.parent.relative_to(base)
        if (folder / index.name).exists():
            continue
        folder.mkdir(parents=True, exist_ok=True)
        for data in index.parent.glob(f"{glob.escape(index.stem)}.*.nbc"):
            shutil.copy2(data, folder / data.name)
        shutil.copy2(index, folder / index.name)  # last: an index never names data that is not there
    os.environ["NUMBA_CACHE_DIR"] = str(own)


_numba_cache_per_worker()  # at import: before any test module (or a conftest beneath) imports core.jit


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def _by_file_scheduling(config: pytest.Config) -> bool:
    """--dist loadgroup: the controller's option; xdist's workers have dist "no" and loadgroup True instead."""
    return getattr(config.option, "dist", "no") == "loadgroup" or bool(getattr(config.option, "loadgroup", False))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """--dist loadgroup, with each test file a group of its own unless SAME_WORKER or an xdist_group mark says."""
    if not _by_file_scheduling(config):
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FileScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            if nodeid.rfind("@") > nodeid.rfind("]"):  # xdist_group: loadgroup appends "@name" to the node id
                return nodeid.rsplit("@", 1)[-1]
            f = _file_of(nodeid)
            return SAME_WORKER.get(f, f)

    config.option.loadscopereorder = False  # units in collection order (SLOW_FIRST), not by their test counts
    return FileScheduling(config, log)


@pytest.hookimpl(tryfirst=True)  # before xdist's own (which appends the xdist_group names to the node ids)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """In xdist workers, the files of SLOW_FIRST first (every worker collects, and orders, the same way)."""
    if not hasattr(config, "workerinput") or not _by_file_scheduling(config):
        return
    rank = {f: i for i, f in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(_file_of(item.nodeid), len(rank)))  # stable: file order kept


class FileProgress:
    """The xdist controller's progress: one line per finished test file (see "Parallel runs" above)."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config
        self.tr = config.pluginmanager.get_plugin("terminalreporter")
        self.todo: dict[str, int] = {}  # file -> tests not finished
        self.outcomes: dict[str, dict[str, int]] = {}
        self.workers: dict[str, set[str]] = {}
        self.started: dict[str, float] = {}
        self.total = self.done = 0
        self.live = True  # False once the run is over: the summary needs pytest's own status words

    @pytest.hookimpl(wrapper=True)
    def pytest_report_teststatus(self, report, config):
        category, letter, word = yield
        if not self.live or not isinstance(report, pytest.TestReport):
            return category, letter, word
        if letter or word:
            counts = self.outcomes.setdefault(_file_of(report.nodeid), {})
            counts[category] = counts.get(category, 0) + 1
            if report.failed:
                node = getattr(report, "node", None)
                where = f"[{node.gateway.id}] " if node is not None else ""
                self.tr.ensure_newline()
                self.tr.write_line(f"{where}{word if isinstance(word, str) else word[0]} {report.nodeid}", red=True)
        return category, "", ""  # no letter: this plugin writes the lines

    def pytest_xdist_node_collection_finished(self, node, ids: list[str]) -> None:
        if self.todo:
            return  # every worker collects the same tests
        for nodeid in ids:
            f = _file_of(nodeid)
            self.todo[f] = self.todo.get(f, 0) + 1
        self.total = len(ids)

    def pytest_runtest_logstart(self, nodeid: str, location) -> None:
        self.started.setdefault(_file_of(nodeid), time.monotonic())

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        node = getattr(report, "node", None)
        if node is not None:
            self.workers.setdefault(_file_of(report.nodeid), set()).add(node.gateway.id)

    def pytest_runtest_logfinish(self, nodeid: str, location) -> None:
        f = _file_of(nodeid)
        self.done += 1
        self.todo[f] = self.todo.get(f, 1) - 1
        if self.todo[f] == 0:
            self._line(f)

    def _line(self, f: str) -> None:
        counts = self.outcomes.get(f, {})
        text = ", ".join(f"{n} {category}" for category, n in counts.items()) or "no tests run"
        if self.todo.get(f, 0) > 0:
            text += f", {self.todo[f]} not run"
        seconds = time.monotonic() - self.started.get(f, time.monotonic())
        workers = ",".join(sorted(self.workers.get(f, ())))
        width = len(str(self.total))
        self.tr.ensure_newline()
        self.tr.write_line(f"[{self.done:{width}d}/{self.total}] {f}: {text} in {seconds:.1f} s ({workers})")

    @pytest.hookimpl(tryfirst=True)
    def pytest_sessionfinish(self) -> None:
        for f, left in self.todo.items():  # a worker that crashed leaves its file unfinished
            if 0 < left and f in self.started:
                self._line(f)
        self.live = False


@pytest.hookimpl(trylast=True)  # after xdist has set up its controller
def pytest_configure(config: pytest.Config) -> None:
    controller = config.pluginmanager.has_plugin("dsession") and not hasattr(config, "workerinput")
    if controller and config.get_verbosity() <= 0 and config.pluginmanager.has_plugin("terminalreporter"):
        config.pluginmanager.register(FileProgress(config), "slscan-file-progress")
