"""Cutting a dump's frame sets into chunks: the cluster's tasks."""

from __future__ import annotations

from dataclasses import dataclass

from app.framesets import FrameIndexSet

DEFAULT_CHUNK_SETS = 60  # ~2-4 s of one core at 640x480: scheduling costs a few ms a task (docs/performance.md)


@dataclass(frozen=True)
class Chunk:
    """Consecutive frame sets of one dump, decoded by one task; set k of the chunk is output number first_set + k."""

    dump: int  # index of the dump among the run's dumps
    number: int  # the chunk's number within its dump (its marker's name)
    first_set: int
    sets: tuple[FrameIndexSet, ...]

    @property
    def last_set(self) -> int:
        return self.first_set + len(self.sets) - 1

    def frames(self) -> list[int]:
        """The dump frames the chunk reads (its sets' frames and their previous frames), in order. Sliding pairs
        share frames, so a chunk shares one frame (two with the previous frame) with its neighbour."""
        needed: set[int] = set()
        for fs in self.sets:
            needed.update(fs.indices)
            if fs.previous is not None:
                needed.add(fs.previous)
        return sorted(needed)


def make_chunks(sets: list[FrameIndexSet], size: int, dump: int = 0) -> list[Chunk]:
    """sets (numbered 0.. in order, as the local path numbers its outputs) in chunks of `size`, the last shorter."""
    if size < 1:
        raise ValueError(f"chunk size {size}: must be at least 1")
    return [
        Chunk(dump, k, start, tuple(sets[start : start + size])) for k, start in enumerate(range(0, len(sets), size))
    ]
