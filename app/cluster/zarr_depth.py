"""`--zarr`: a dump's depth maps also as one chunked Zarr array, `OUT/<sub>/depth.zarr` (docs/formats.md, "Depth as
Zarr"), that xarray and dask open lazily: `depth` (set, y, x) float32 mm, 0 = none, with `timestamp_ns` and
`frame_id` (set,) of each set's newest frame as coordinates.

Invariants: the store's metadata and coordinates are written by the client before any task runs, under a temporary
name renamed into place; its Zarr chunks along `set` are the run's chunks (chunk_sets sets), so chunk k of the run
is Zarr chunk k and no two tasks write one file. A task encodes its chunk into a copy of the array's metadata in its
partial folder and renames the one chunk file into the store: whole or absent, like every other output.
"""

from __future__ import annotations

import os
import shutil
import uuid
import warnings
from pathlib import Path

import numpy as np

from app.cluster.chunks import Chunk
from core.dump import Dump
from core.errors import InputError

STORE = "depth.zarr"
EXTRA = "pip install 'slscan[cluster]'"


def _zarr():
    try:
        import zarr
    except ImportError:
        raise InputError(f"--zarr needs zarr, which is not installed: {EXTRA}") from None
    return zarr


def require_zarr() -> None:
    """An InputError naming the extra when zarr is missing (before anything is written)."""
    _zarr()


def create_store(folder: Path, dump: Dump, sets: list, shape: tuple[int, int], chunk_sets: int) -> None:
    """folder/depth.zarr with its metadata and coordinates and no depth chunk yet (absent chunks read as 0); an
    existing store (a resumed run) is left as it is."""
    zarr = _zarr()
    target = folder / STORE
    if target.exists():
        return
    tmp = folder / f".{STORE}.{uuid.uuid4().hex[:8]}.partial"
    try:
        group = zarr.open_group(str(tmp), mode="w-")
        h, w = shape
        n = len(sets)
        depth = group.create_array(
            "depth",
            shape=(n, h, w),
            chunks=(chunk_sets, h, w),
            dtype="float32",
            fill_value=0.0,
            dimension_names=("set", "y", "x"),
        )
        depth.attrs.update({"units": "mm", "coordinates": "timestamp_ns frame_id", "zero": "no depth"})
        newest = [dump.frames[fs.indices[fs.newest_index]] for fs in sets]
        for name, values in (
            ("timestamp_ns", [f.timestamp_ns for f in newest]),
            ("frame_id", [f.frame_id for f in newest]),
        ):
            a = group.create_array(name, shape=(n,), chunks=(max(1, n),), dtype="int64", dimension_names=("set",))
            a[:] = np.asarray(values, dtype=np.int64)
        group.attrs.update({"dump": str(dump.folder), "note": "set n is the files' NNNNNN; newest frame's tags"})
        # consolidated, so xarray opens it in one read: the metadata never changes once the store is in place
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (zarr: consolidated metadata is not yet part of the v3 spec)
            zarr.consolidate_metadata(str(tmp))
        os.replace(tmp, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def chunk_file(chunk: Chunk) -> str:
    """The chunk's file inside the store, relative to the dump's output folder (Zarr v3's default key encoding)."""
    return f"{STORE}/depth/c/{chunk.number}/0/0"


def write_chunk(folder: Path, partial: Path, chunk: Chunk, depths: list[np.ndarray]) -> dict[str, int]:
    """Encode the chunk's depth maps as its Zarr chunk and rename it into folder/depth.zarr; returns {file: size}
    (empty when every value is 0: Zarr stores no chunk of fill values)."""
    zarr = _zarr()
    scratch = partial / "zarr" / "depth"
    scratch.mkdir(parents=True)
    shutil.copy2(folder / STORE / "depth" / "zarr.json", scratch / "zarr.json")  # the same shape, chunks, codecs
    array = zarr.open_array(str(scratch), mode="r+")
    array[chunk.first_set : chunk.first_set + len(depths)] = np.stack(depths)
    encoded = scratch / "c" / str(chunk.number) / "0" / "0"
    if not encoded.is_file():
        return {}
    name = chunk_file(chunk)
    size = encoded.stat().st_size
    (folder / name).parent.mkdir(parents=True, exist_ok=True)
    os.replace(encoded, folder / name)
    return {name: size}
