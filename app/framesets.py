"""Grouping tagged frames into complete frame sets (one pattern cycle each), never guessing.

Used by `slscan decode` on dumps and meant for the live pipeline: the input is any sequence of
(frame_id, pattern) tags, the output the index lists of the frames that form decodable sets.

Rules (a swapped two-shot pair inverts every sign and decodes to wrong but plausible stripes,
so tags are checked, never assumed):
- one-shot: every frame tagged 0 is a set by itself.
- two-shot: two frames with consecutive frame_id whose tags are {0, 1} in either order. Pairs
  slide (frames 1-2, 2-3, 3-4, ...) so 60 frames/s give up to 60 sets/s; a frame_id gap or a
  wrong tag breaks the pair. The order is reported so the decoder knows which is frame 1.
- graycode (n patterns): n frames with consecutive frame_id tagged 0, 1, ..., n-1 in order.
- a white-light texture frame (tagged texture_pattern = n_patterns, one past the patterns) is in no set: every rule
  above needs tags below n_patterns, and the frames on either side of it are not consecutive.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from app.schemes import get_scheme


@dataclass(frozen=True)
class FrameIndexSet:
    """Indices (into the caller's frame list) of one complete set, in pattern order."""

    indices: tuple[int, ...]  # indices[p] is the frame that saw pattern p
    first: int  # index of the earliest frame of the set (for ordering / naming)
    reversed_order: bool = False  # two-shot: the pattern-1 frame came first in time
    previous: int | None = None  # two-shot: the frame just before the set, if consecutive (it saw the newest's pattern)

    @property
    def newest_index(self) -> int:
        """The pattern index of the set's frame taken last."""
        return 0 if self.reversed_order else len(self.indices) - 1


@dataclass
class FrameSetStats:
    sets: int = 0
    frames: int = 0
    gaps: int = 0  # frame_id jumps (dropped frames)
    bad_tags: int = 0  # tags outside the scheme or a repeated tag where a pair needed the other one
    textures: int = 0  # white-light texture frames (in no set)


def group_frame_sets(
    tags: Sequence[tuple[int, int]],
    scheme: str,
    n_patterns: int,
    *,
    sliding: bool = True,
    texture_pattern: int | None = None,
) -> tuple[list[FrameIndexSet], FrameSetStats]:
    """Group (frame_id, pattern) tags, in capture order, into complete frame sets.

    sliding=False makes two-shot pairs disjoint (frames 1-2, 3-4, ...) instead of sliding. texture_pattern: the tag
    of white-light texture frames (n_patterns), counted apart from bad tags; no set takes one either way.
    """
    if texture_pattern is not None and texture_pattern != n_patterns:
        raise ValueError(f"texture_pattern {texture_pattern} must be n_patterns ({n_patterns}): one past the patterns")
    stats = FrameSetStats(frames=len(tags))
    sets: list[FrameIndexSet] = []
    for i in range(1, len(tags)):
        if tags[i][0] != tags[i - 1][0] + 1:
            stats.gaps += 1
    for _, pat in tags:
        if pat == texture_pattern:
            stats.textures += 1
        elif not 0 <= pat < n_patterns:
            stats.bad_tags += 1
    frames_per_set = get_scheme(scheme).shots  # an unknown scheme is an InputError
    if frames_per_set == 1:
        sets = [FrameIndexSet((i,), i) for i, (_, p) in enumerate(tags) if p == 0]
    elif frames_per_set == 2:
        i = 0
        while i + 1 < len(tags):
            (fa, pa), (fb, pb) = tags[i], tags[i + 1]
            if fb == fa + 1 and {pa, pb} == {0, 1}:
                order = (i, i + 1) if pa == 0 else (i + 1, i)
                before = i - 1 if i > 0 and tags[i - 1] == (fa - 1, pb) else None  # (pb: the newest frame's pattern)
                sets.append(FrameIndexSet(order, i, reversed_order=pa == 1, previous=before))
                i += 1 if sliding else 2
            else:
                if fb == fa + 1 and pa == pb:
                    stats.bad_tags += 1
                i += 1
    else:  # one frame per pattern, in pattern order (Gray code)
        i = 0
        while i + n_patterns <= len(tags):
            ok = all(
                tags[i + j][1] == j and (j == 0 or tags[i + j][0] == tags[i + j - 1][0] + 1) for j in range(n_patterns)
            )
            if ok:
                sets.append(FrameIndexSet(tuple(range(i, i + n_patterns)), i))
                i += n_patterns
            else:
                i += 1
    stats.sets = len(sets)
    return sets, stats
