"""What a Dask worker runs: decode one chunk of a dump into the output folder (app/offline_decode.py's per-set work,
the same bytes as the local path).

The worker reads the frames from the dump folder itself (no frames pass through the scheduler) and builds the
dump's decoder once per worker thread (calibration tables, compiled kernels), kept across tasks. Files are written in a
partial folder of the task's own and renamed into place one by one, then the chunk's marker (manifest.py): a kill
at any point leaves no half-written file under a final name and no marker for an incomplete chunk.
"""

from __future__ import annotations

import os
import shutil
import socket
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.cluster.chunks import Chunk
from app.cluster.manifest import marker_path, partial_folder, write_yaml_atomically
from app.cluster.zarr_depth import write_chunk
from app.offline_decode import DecodeSettings, SetDecoder

_DECODERS: OrderedDict[tuple[str, int], SetDecoder] = OrderedDict()  # (run's dump key, thread) -> decoder
_KEEP_DECODERS = 4  # per process: a run of many dumps goes through them in order
_LOCK = threading.Lock()


@dataclass(frozen=True)
class ChunkResult:
    dump: int
    number: int
    sets: int
    empty: int  # sets that decoded to nothing
    worker: str  # host:pid
    wall_s: float  # the task's time on its worker, decoder set-up included
    cpu_s: float  # CPU time of the thread that ran it (decoder and writers run there), decoder set-up excluded
    setup_s: float  # of wall_s: building the decoder (0 when the worker had it)
    empty_reason: str
    depth_range_problem: str | None
    malloc_trim: str | None  # the worker's MALLOC_TRIM_THRESHOLD_ (a Dask nanny sets it; it slows the decoder)


def worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _decoder(key: str, settings: DecodeSettings) -> tuple[SetDecoder, float]:
    """The worker thread's decoder of this dump (built on first use), and the seconds spent building it now."""
    k = (key, threading.get_ident())
    with _LOCK:
        found = _DECODERS.get(k)
        if found is not None:
            _DECODERS.move_to_end(k)
            return found, 0.0
    t0 = time.perf_counter()
    built = SetDecoder(settings)
    with _LOCK:
        _DECODERS[k] = built
        while len(_DECODERS) > _KEEP_DECODERS:
            _DECODERS.popitem(last=False)
    return built, time.perf_counter() - t0


def decode_chunk(
    key: str, settings: DecodeSettings, chunk: Chunk, out: str, sub: str, zarr: bool = False
) -> ChunkResult:
    """Decode chunk's sets into out/sub/ (as the local path names them; with zarr, their depth maps also as the
    chunk's Zarr chunk of out/sub/depth.zarr, which the client created), then write the chunk's marker."""
    t0, c0 = time.perf_counter(), time.thread_time()
    out_path = Path(out)
    final = out_path / sub
    partial = partial_folder(out_path, chunk, socket.gethostname(), os.getpid())
    files_dir = partial / "files"
    files_dir.mkdir(parents=True)
    try:
        worker, setup_s = _decoder(key, settings)
        c_setup = time.thread_time() - c0
        # Sliding pairs share frames: each frame is read once per chunk (the decoder's Bayer cache relies on
        # seeing the same array object again, which this also gives it).
        cache: OrderedDict[int, np.ndarray] = OrderedDict()

        def load(i: int) -> np.ndarray:
            if i not in cache:
                cache[i] = worker.dump.load_frame(i)
                while len(cache) > 4:
                    cache.popitem(last=False)
            return cache[i]

        empty = 0
        depths = []
        for k, fs in enumerate(chunk.sets):
            res = worker.decode_and_write(chunk.first_set + k, fs, files_dir, load)
            empty += not res.stripes.valid.any()
            if zarr:
                depths.append(res.depth)
        files = {}
        for f in sorted(files_dir.iterdir()):
            files[f.name] = f.stat().st_size
            os.replace(f, final / f.name)  # whole, under its final name; an earlier attempt's copy is the same bytes
        if zarr:
            files.update(write_chunk(final, partial, chunk, depths))
        write_yaml_atomically(
            marker_path(out_path, sub, chunk),
            {"first_set": chunk.first_set, "sets": len(chunk.sets), "worker": worker_id(), "files": files},
        )
    finally:
        shutil.rmtree(partial, ignore_errors=True)
    dec = worker.decoder
    return ChunkResult(
        chunk.dump,
        chunk.number,
        len(chunk.sets),
        empty,
        worker_id(),
        time.perf_counter() - t0,
        time.thread_time() - c0 - c_setup,
        setup_s,
        dec.empty_reason(),
        dec.depth_range_problem,
        os.environ.get("MALLOC_TRIM_THRESHOLD_"),
    )
