"""The output folder of a cluster run: its manifest (what the run decodes, with which options) and the per-chunk
markers that say which chunks are complete, so that a rerun resumes instead of redoing (docs/formats.md,
"Decode run").

Invariants: a file under a final name in OUT is always whole (written under .decode-run/partial/, then renamed);
a chunk's marker is written, whole, only after all its files are in place, and lists them with their sizes, so a
chunk with a marker whose files are all there at those sizes is complete; the manifest is written before any
output and never changes.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import uuid
from pathlib import Path

import yaml

from app.cluster.chunks import Chunk
from core.errors import InputError
from core.yamlfile import load_yaml_mapping

MANIFEST = "decode-run.yaml"
RUN_FOLDER = ".decode-run"  # markers/<dump subfolder>/chunk-NNNNNN.yaml, partial/<a task's files being written>
FORMAT = "slscan-decode-run"
VERSION = 1


def run_manifest(dumps: list[dict], options: dict) -> dict:
    """dumps: per dump {folder, index_sha256, subfolder, sets, chunks}; options: everything that changes the bytes
    written or the chunking."""
    return {"format": FORMAT, "version": VERSION, "options": options, "dumps": dumps}


def index_digest(dump_folder: Path) -> str:
    """sha256 of a dump's index: a dump that changed since the earlier run (repaired, grown) is not resumed."""
    return hashlib.sha256((dump_folder / "dump.yaml").read_bytes()).hexdigest()


def check_out(out: Path, manifest: dict) -> bool:
    """Whether OUT can take the run, writing nothing: True if it holds this same run's manifest (resume), False if
    it is absent or empty. Refuses (InputError) a symlink, a file, an OUT with anything else in it, or one holding a
    run of other dumps or options."""
    if out.is_symlink():  # (an output is never written through a symlink: it may lead anywhere)
        raise InputError(f"{out}: is a symlink; give the folder itself")
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    if not (out.exists() and any(out.iterdir())):
        return False
    path = out / MANIFEST
    if not path.is_file():
        raise InputError(
            f"{out}: folder exists, is not empty and holds no {MANIFEST} of an earlier run "
            "(choose another path or remove it)"
        )
    earlier = load_yaml_mapping(path)
    if earlier.get("format") != FORMAT or earlier.get("version") != VERSION:
        raise InputError(f"{path}: not a {FORMAT} version {VERSION} manifest")
    if earlier != yaml.safe_load(yaml.safe_dump(manifest)):  # (as read back: tuples are lists)
        raise InputError(
            f"{path}: {_difference(earlier, manifest)}; resume it with the same command, or choose another --out"
        )
    return True


def create_out(out: Path, manifest: dict, subfolders: list[str], resumed: bool) -> None:
    """Write the manifest (a new run) and the folders the tasks write into."""
    if not resumed:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{out}: cannot create the folder ({exc.strerror})") from None
        write_yaml_atomically(out / MANIFEST, manifest)
    for sub in subfolders:
        (out / sub).mkdir(exist_ok=True)
        (out / RUN_FOLDER / "markers" / _marker_folder(sub)).mkdir(parents=True, exist_ok=True)
    (out / RUN_FOLDER / "partial").mkdir(parents=True, exist_ok=True)


def _difference(earlier: dict, now: dict) -> str:
    if earlier.get("options") != now.get("options"):
        changed = sorted(
            k
            for k in set(earlier.get("options", {})) | set(now["options"])
            if earlier.get("options", {}).get(k) != now["options"].get(k)
        )
        return f"an earlier run with other options ({', '.join(changed)})"
    before = [d.get("folder") for d in earlier.get("dumps", [])]
    if before != [d["folder"] for d in now["dumps"]]:
        return f"an earlier run of other dumps ({', '.join(map(str, before))})"
    return "an earlier run of these dumps as they were then (a dump's index has changed since)"


def _marker_folder(sub: str) -> str:
    return "_" if sub == "." else sub


def marker_path(out: Path, sub: str, chunk: Chunk) -> Path:
    return out / RUN_FOLDER / "markers" / _marker_folder(sub) / f"chunk-{chunk.number:06d}.yaml"


def chunk_complete(out: Path, sub: str, chunk: Chunk) -> bool:
    """The chunk's marker is there and every file it lists is in place at its size."""
    path = marker_path(out, sub, chunk)
    if not path.is_file():
        return False
    try:
        marker = yaml.safe_load(path.read_text())
        files = marker["files"]
        if marker["first_set"] != chunk.first_set or marker["sets"] != len(chunk.sets):
            return False
        return all(
            (out / sub / name).is_file() and (out / sub / name).stat().st_size == size for name, size in files.items()
        )
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return False  # an unreadable marker: the chunk is decoded again


def partial_folder(out: Path, chunk: Chunk, host: str, pid: int) -> Path:
    """Where a task writes its files before renaming them into place (unique per attempt; the pid tells whose)."""
    name = f"d{chunk.dump}-c{chunk.number:06d}-p{pid}-{host}-{uuid.uuid4().hex[:8]}"
    return out / RUN_FOLDER / "partial" / name


def remove_partials(out: Path) -> int:
    """Remove what killed tasks left in .decode-run/partial/ (nothing there is under a final name); returns how many
    folders. Called by the client when no task of this run is running."""
    folder = out / RUN_FOLDER / "partial"
    if not folder.is_dir():
        return 0
    n = 0
    for p in folder.iterdir():
        shutil.rmtree(p, ignore_errors=True)
        n += 1
    return n


def write_yaml_atomically(path: Path, data: dict) -> None:
    """path appears whole or not at all (a temporary sibling renamed into place)."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    tmp.write_text(yaml.safe_dump(data, sort_keys=False))
    os.replace(tmp, path)
