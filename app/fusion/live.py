"""Fusion in a live session: every decoded scan is offered to one fusion thread, which never holds capture up.

The decode workers hand their results to `offer` (a one-slot mailbox: a scan still waiting when a newer one comes
is replaced and counted `late`); the fusion thread tracks every scan it takes, and integrates an accepted one only
when no newer scan is already waiting (else `skipped`): tracking keeps up first, integration takes what is left.
"""

from __future__ import annotations

import threading
from typing import Any

from app.decode.mosaic import to_rgb
from app.fusion.colour import scan_colour
from app.fusion.fuser import Fuser
from app.recorder import lower_thread_priority
from core.calibration import Calibration

FUSION_NICENESS = 10  # the capture loop and the decode workers come first


class LiveFusion:
    def __init__(
        self,
        calibration: Calibration,
        depth_range_mm: tuple[float, float],
        volume_mm: tuple[float, ...] | None,
        voxel_mm: float,
    ) -> None:
        self.fuser = Fuser(calibration, depth_range_mm, volume_mm, voxel_mm)
        self._cond = threading.Condition()
        self._slot: Any = None
        self._stop = False
        self.offered = 0
        self.late = 0  # replaced in the mailbox before the fusion thread took them
        self.skipped = 0  # tracked and accepted, not integrated (a newer scan was waiting)
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, name="fusion", daemon=True)
        self._thread.start()

    def offer(self, result: Any) -> None:
        """LivePipeline's on_result (a decode worker's thread): keep the newest, never wait."""
        with self._cond:
            self.offered += 1
            if self._slot is not None:
                self.late += 1
            self._slot = result
            self._cond.notify()

    def _run(self) -> None:
        lower_thread_priority(FUSION_NICENESS)
        while True:
            with self._cond:
                while self._slot is None and not self._stop:
                    self._cond.wait()
                if self._slot is None:
                    return
                res, self._slot = self._slot, None
            try:
                frames = [to_rgb(f.image, f.mosaic) for f in res.frameset.frames]
                scan = self.fuser.scan(res.depth, scan_colour(frames), res.frameset.newest.frame_id)
                tracked = self.fuser.track(scan)
                if tracked.ok:
                    with self._cond:
                        newer = self._slot is not None
                    if newer:
                        self.skipped += 1
                    else:
                        self.fuser.integrate(scan, tracked.pose)
            except Exception as exc:  # reported with the session's figures; capture goes on regardless
                self.error = f"{type(exc).__name__}: {exc}"
                return

    def stop(self) -> None:
        """Finish the scan in hand and the one waiting, then end the thread."""
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join()

    def summary(self) -> str:
        s = self.fuser.stats
        return (
            f"fusion: {s.scans} of {self.offered} scans tracked ({self.late} late), {s.integrated} integrated "
            f"({self.skipped} skipped for a newer scan), {s.dropped} failed registration"
        )
