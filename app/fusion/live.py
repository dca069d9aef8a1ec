"""Fusion in a live session: every decoded scan is offered to one fusion thread, which never holds capture up.

The decode workers hand their results to `offer` (a one-slot mailbox: a scan still waiting when a newer one comes
is replaced and counted `late`); the fusion thread tracks every scan it takes, and integrates an accepted one when
no newer scan is already waiting or when one is due, INTEGRATE_EVERY_S apart (app/fusion/integration_schedule.py;
else `skipped`): tracking keeps up first, and integration still gets its share when tracking alone takes all the
time there is.

The thread first warms fusion up (app/fusion/warm_up.py: Open3D and the tracking kernels loaded before the first
real scan); a headless session waits for that before capture starts (`wait_ready`), the operator window does not
(its state line says "starting" meanwhile).

`save` (the operator window's key, on a thread of its own) takes the model's mesh and poses between two scans (one
lock, held by the fusion thread for each scan and by `save` while it copies the model out), so a mesh is never read
from a volume half-way through an integration; scans that come meanwhile wait in the mailbox and count late.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

from app.decode.mosaic import to_rgb
from app.fusion.colour import scan_colour
from app.fusion.fuser import Fuser
from app.fusion.integration_schedule import IntegrationSchedule
from app.fusion.warm_up import warm_up
from app.recorder import lower_thread_priority
from core.calibration import Calibration

FUSION_NICENESS = 10  # the capture loop and the decode workers come first
INTEGRATE_EVERY_S = 0.08  # 12.5 integrations a second (each ~12 ms of CPU) when scans queue up: >= 10 with margin


class LiveFusion:
    def __init__(
        self,
        calibration: Calibration,
        depth_range_mm: tuple[float, float],
        volume_mm: tuple[float, ...] | None,
        voxel_mm: float,
    ) -> None:
        self.fuser = Fuser(calibration, depth_range_mm, volume_mm, voxel_mm)
        self._warm_up_args = (calibration, depth_range_mm, volume_mm, voxel_mm)
        self._ready = threading.Event()
        self._cond = threading.Condition()
        self._slot: Any = None
        self._stop = False
        self.offered = 0
        self.late = 0  # replaced in the mailbox before the fusion thread took them
        self.skipped = 0  # tracked and accepted, not integrated (a newer scan was waiting)
        self.error: str | None = None
        self._lock = threading.Lock()  # one scan's track + integrate, or a save's copy of the model
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

    def wait_ready(self, timeout_s: float | None = None) -> bool:
        """Wait until the warm-up is over (or failed: see error); whether it is."""
        return self._ready.wait(timeout_s)

    def _run(self) -> None:
        lower_thread_priority(FUSION_NICENESS)
        try:
            warm_up(*self._warm_up_args)
        except Exception as exc:  # reported like a failed scan; capture goes on regardless
            self.error = f"{type(exc).__name__}: {exc}"
            return
        finally:
            self._ready.set()
        schedule = IntegrationSchedule(INTEGRATE_EVERY_S)
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
                with self._lock:
                    tracked = self.fuser.track(scan)
                    if tracked.ok:
                        with self._cond:
                            newer = self._slot is not None
                        if not schedule.wants(time.monotonic(), newer):
                            self.skipped += 1
                        else:
                            self.fuser.integrate(scan, tracked.pose)
                            schedule.integrated(time.monotonic())
            except Exception as exc:  # reported with the session's figures; capture goes on regardless
                self.error = f"{type(exc).__name__}: {exc}"
                return

    def stop(self) -> None:
        """Finish the scan in hand and the one waiting, then end the thread."""
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def state(self) -> str:
        """One line for the operator: tracking / lost / stopped, and the counts."""
        s = self.fuser.stats
        if self.error is not None:
            state = "FAILED"
        elif not self.running:
            state = "stopped"
        elif not self._ready.is_set():
            state = "starting"
        elif s.scans == 0:
            state = "waiting"
        elif s.dropped_in_a_row:
            state = f"LOST ({s.dropped_in_a_row} in a row)"
        else:
            state = "tracking"
        return (
            f"fusion {state}: {s.integrated} fused, {s.dropped} dropped, {self.late} late, {self.skipped} skipped; "
            f"model {len(self.fuser.tracker.map)} points"
        )

    def save(self, out: str | Path) -> tuple[Path, Path, Path, int]:
        """The mesh (PLY + OBJ, as `slscan fuse` writes them) and the trajectory beside them; (ply, obj, csv, scans).

        Safe while the fusion thread runs (it waits for the copy); InputError when there is no surface yet."""
        from app.fusion.mesh_io import mesh_paths, write_mesh
        from core.trajectory import write_trajectory

        with self._lock:
            mesh = self.fuser.mesh()
            poses = list(self.fuser.poses)
            scans = self.fuser.stats.integrated
        ply, obj = write_mesh(mesh, out)
        trajectory = mesh_paths(out)[0].with_suffix(".trajectory.csv")
        write_trajectory(trajectory, poses)
        return ply, obj, trajectory, scans

    def summary(self) -> str:
        s = self.fuser.stats
        return (
            f"fusion: {s.scans} of {self.offered} scans tracked ({self.late} late), {s.integrated} integrated "
            f"({self.skipped} skipped for a newer scan), {s.dropped} failed registration"
            + (f"; the model started over {s.restarts}x (a scan long after its first)" if s.restarts else "")
        )
