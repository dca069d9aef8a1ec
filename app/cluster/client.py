"""Connecting to a Dask scheduler (`tcp://host:8786`) or starting a LocalCluster (`local[:N]`) for a run."""

from __future__ import annotations

import contextlib
import logging
import os
import re
from collections.abc import Iterator
from typing import Any

from core.errors import InputError

DEFAULT_CONNECT_TIMEOUT_S = 10.0
EXTRA = "pip install 'slscan[cluster]'"
MALLOC_TRIM_KEY = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"
_ADDRESS = re.compile(r"^(tcp|tls|ucx|inproc)://[^\s/]+$")


def require_distributed() -> Any:
    """The dask.distributed module, or an InputError naming the extra that installs it."""
    try:
        import distributed
    except ImportError:
        raise InputError(f"--scheduler needs dask.distributed, which is not installed: {EXTRA}") from None
    return distributed


def parse_address(text: str) -> tuple[str, int | str]:
    """("local", workers) for local / local:N, ("remote", address) for scheme://host:port; else an InputError."""
    if text == "local":
        return "local", os.cpu_count() or 1
    if text.startswith("local:"):
        n = text[len("local:") :]
        if not n.isdigit() or int(n) < 1:
            raise InputError(f"--scheduler {text}: local:N needs N >= 1 worker processes")
        return "local", int(n)
    if not _ADDRESS.match(text):
        raise InputError(f"--scheduler {text}: expected tcp://host:port (a Dask scheduler) or local[:N]")
    return "remote", text


@contextlib.contextmanager
def open_client(address: str, timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S) -> Iterator[Any]:
    """A distributed.Client on the scheduler at address, or on a LocalCluster of N single-threaded worker processes
    (closed on exit). A scheduler that does not answer within timeout_s is an InputError, nothing written."""
    distributed = require_distributed()
    import dask

    kind, value = parse_address(address)
    if kind == "local":
        # One thread per process: the decoder holds the GIL for its Python parts, processes scale. Dask's nannies set
        # MALLOC_TRIM_THRESHOLD_ in their workers, which turns off glibc's adaptive mmap threshold: every frame-sized
        # array is then mmap'd and zero-filled afresh, +50-80 % CPU a set (docs/performance.md); left unset here.
        with dask.config.set({MALLOC_TRIM_KEY: None}):
            cluster = distributed.LocalCluster(
                n_workers=int(value),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
        try:
            with distributed.Client(cluster, timeout=timeout_s) as client:
                yield client
        finally:
            cluster.close()
        return
    try:
        client = distributed.Client(str(value), timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        why = "" if isinstance(exc, TimeoutError) or "Timed out" in str(exc) else f" ({exc})"
        raise InputError(f"--scheduler {value}: no Dask scheduler answered within {timeout_s:g} s{why}") from None
    with client:
        yield client


def worker_pids(client: Any) -> dict[str, int]:
    """Worker address -> pid, as the workers report it."""
    return client.run(os.getpid)
