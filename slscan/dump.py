"""`slscan.read_dump(path)`: a frame dump (docs/formats.md, "Frame dump") as frame sets, patterns, calibration."""

from __future__ import annotations

import bisect
import os
from collections.abc import Iterator, Sequence
from functools import cached_property
from pathlib import Path
from typing import overload

from app.framesets import FrameIndexSet, group_frame_sets
from core.calibration import Calibration
from core.dump import Dump as _DumpIndex
from core.dump import read_dump as _read_index
from core.errors import InputError
from core.patterns import PatternSet
from slscan.frameset import FrameSet


class Dump:
    """A frame dump on disk. Frames are read when a frame set is taken, not before."""

    def __init__(self, index: _DumpIndex) -> None:
        self._index = index
        self.path: Path = index.folder
        self.scheme: str = index.scheme
        self.depth_range_mm: tuple[float, float] | None = index.depth_range_mm()
        self.mosaic: str | None = index.mosaic  # the Bayer mosaic of raw one-channel frames, None for RGB

    @cached_property
    def patterns(self) -> PatternSet:
        """The pattern set the frames saw (the dump's pattern export, images checked)."""
        patterns = self._index.patterns()
        if patterns.scheme != self.scheme:
            raise InputError(f"{self.path}: dump scheme {self.scheme!r} but its patterns say {patterns.scheme!r}")
        return patterns

    @cached_property
    def calibration(self) -> Calibration | None:
        """The dump's calibration, None if it has none."""
        return self._index.calibration()

    def __len__(self) -> int:
        """The number of frames (not sets)."""
        return len(self._index.frames)

    def frame_sets(self, *, sliding: bool = True) -> FrameSets:
        """The complete frame sets, in capture order, from the frames' tags (a frame-id gap or a wrong tag is never
        paired; white-light texture frames belong to no set, each set carries the nearest one before it as its
        `texture`). Two-shot pairs slide (frames 1-2, 2-3, ...) unless sliding=False (1-2, 3-4, ...)."""
        tags = [(f.frame_id, f.pattern) for f in self._index.frames]
        textures = self._index.texture_indices()  # (checks the dump's texture tag)
        n = len(self.patterns)
        sets, _ = group_frame_sets(tags, self.scheme, n, sliding=sliding, texture_pattern=n if textures else None)
        return FrameSets(self._index, sets, textures)


class FrameSets(Sequence[FrameSet]):
    """The frame sets of a dump: a sequence whose items are read from disk when taken."""

    def __init__(self, index: _DumpIndex, sets: list[FrameIndexSet], textures: list[int]) -> None:
        self._index = index
        self._sets = sets
        self._textures = textures  # frame indices of the texture frames, in capture order

    def __len__(self) -> int:
        return len(self._sets)

    @overload
    def __getitem__(self, i: int) -> FrameSet: ...
    @overload
    def __getitem__(self, i: slice) -> list[FrameSet]: ...
    def __getitem__(self, i: int | slice) -> FrameSet | list[FrameSet]:
        if isinstance(i, slice):
            return [self._load(s) for s in self._sets[i]]
        return self._load(self._sets[i])

    def __iter__(self) -> Iterator[FrameSet]:
        for s in self._sets:
            yield self._load(s)

    def _load(self, s: FrameIndexSet) -> FrameSet:
        index = self._index
        records = [index.frames[i] for i in s.indices]
        previous = index.load_frame(s.previous) if s.previous is not None else None
        k = bisect.bisect_left(self._textures, s.first) - 1  # the nearest texture frame taken before the set
        texture = index.load_frame(self._textures[k]) if k >= 0 else None
        return FrameSet(
            [index.load_frame(i) for i in s.indices],
            frame_ids=[r.frame_id for r in records],
            timestamps_ns=[r.timestamp_ns for r in records],
            newest=s.newest_index,
            previous=previous,
            texture=texture,
        )


def read_dump(path: str | os.PathLike) -> Dump:
    """Open a frame dump folder (format slscan-dump v1); a missing or malformed one is an InputError naming it."""
    return Dump(_read_index(path))
