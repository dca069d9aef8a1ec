"""What a cluster run did: sets decoded, skipped and failed (with reasons), and each worker's throughput."""

from __future__ import annotations

from dataclasses import dataclass, field

from app.cluster.chunks import Chunk
from app.cluster.task import ChunkResult


@dataclass(frozen=True)
class Failure:
    where: str  # the dump folder
    chunk: Chunk
    reason: str


@dataclass
class WorkerFigures:
    worker: str
    chunks: int = 0
    sets: int = 0
    busy_s: float = 0.0  # the worker's task time (decoder set-up included)
    cpu_s: float = 0.0
    setup_s: float = 0.0

    @property
    def sets_per_s(self) -> float:
        return self.sets / self.busy_s if self.busy_s > 0 else 0.0

    @property
    def cpu_ms_per_set(self) -> float:
        return 1000 * self.cpu_s / self.sets if self.sets else 0.0


def per_worker(results: list[ChunkResult]) -> list[WorkerFigures]:
    """One row per worker that finished a chunk, by worker name."""
    rows: dict[str, WorkerFigures] = {}
    for r in results:
        w = rows.setdefault(r.worker, WorkerFigures(r.worker))
        w.chunks += 1
        w.sets += r.sets
        w.busy_s += r.wall_s
        w.cpu_s += r.cpu_s
        w.setup_s += r.setup_s
    return [rows[k] for k in sorted(rows)]


@dataclass
class RunSummary:
    results: list[ChunkResult] = field(default_factory=list)
    failures: list[Failure] = field(default_factory=list)
    skipped_sets: int = 0
    skipped_chunks: int = 0
    partials_removed: int = 0  # partial folders of killed task attempts (their chunks were retried)
    wall_s: float = 0.0

    @property
    def decoded_sets(self) -> int:
        return sum(r.sets for r in self.results)

    @property
    def failed_sets(self) -> int:
        return sum(len(f.chunk.sets) for f in self.failures)

    def lines(self, out: str) -> list[str]:
        """The summary the command prints on stdout."""
        rate = self.decoded_sets / self.wall_s if self.wall_s > 0 else 0.0
        workers = per_worker(self.results)
        lines = [
            f"cluster run to {out}: {self.decoded_sets} frame set(s) decoded in {len(self.results)} chunk(s) on "
            f"{len(workers)} worker(s) in {self.wall_s:.1f} s ({rate:.1f} sets/s), {self.skipped_sets} skipped "
            f"({self.skipped_chunks} chunk(s) complete from an earlier run), {self.failed_sets} failed"
        ]
        for w in workers:
            lines.append(
                f"  worker {w.worker}: {w.sets} sets in {w.chunks} chunk(s), {w.sets_per_s:.1f} sets/s busy, "
                f"{w.cpu_ms_per_set:.1f} ms CPU a set, decoder set-up {w.setup_s:.1f} s"
            )
        if self.partials_removed:
            lines.append(
                f"  {self.partials_removed} task attempt(s) interrupted (a worker died mid-chunk): their chunks were "
                "decoded again, their partial files removed"
            )
        for f in self.failures:
            lines.append(
                f"  failed: {f.where} chunk {f.chunk.number} (sets {f.chunk.first_set}-{f.chunk.last_set}): {f.reason}"
            )
        return lines
