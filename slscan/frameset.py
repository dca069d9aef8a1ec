"""One complete frame set as the library hands it out: RGB frames in pattern order, with their tags."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


class FrameSet(list):
    """A list of RGB frames (H x W x 3, uint8 or uint16) in pattern order: frames[p] saw pattern p.

    Attributes, where the source knows them (a dump does): `frame_ids` and `timestamps_ns` of the frames in
    pattern order, `newest` (the pattern index of the frame taken last) and `previous` (the frame taken just
    before the set, which saw the newest frame's pattern: a two-shot decoder uses it to find moving pixels) and
    `texture` (the nearest white-light texture frame taken before the set, the object's own colour: it colours
    the scan). A plain list of frames decodes the same way, without motion handling, coloured by the set's own
    frames. A dump of a single-chip camera's raw frames (`Dump.mosaic`) gives one-channel H x W Bayer frames.
    """

    def __init__(
        self,
        frames: Iterable[np.ndarray],
        frame_ids: Iterable[int] = (),
        timestamps_ns: Iterable[int] = (),
        newest: int | None = None,
        previous: np.ndarray | None = None,
        texture: np.ndarray | None = None,
    ) -> None:
        super().__init__(frames)
        self.frame_ids: tuple[int, ...] = tuple(int(i) for i in frame_ids)
        self.timestamps_ns: tuple[int, ...] = tuple(int(t) for t in timestamps_ns)
        self.newest = newest
        self.previous = previous
        self.texture = texture

    @property
    def timestamp_ns(self) -> int | None:
        """The newest frame's timestamp (ns), None if unknown."""
        if not self.timestamps_ns:
            return None
        return self.timestamps_ns[self.newest if self.newest is not None else -1]
