"""The virtual rig as a board source: its board is moved from the keyboard (there is no hand to hold it).

Moving the board re-precomputes the scene (~0.3 s, ~0.8 s on the loaded machine) and detection
costs ~0.13-0.6 s: both run on the preview worker, so a key returns at once and the view follows
(calibration/preview.py). The "next suggested pose" key is served from a prefetch: a second rig
is posed at the next suggestion in the background, rendered and checked for the board; the key
swaps the two rigs, so the new view is on screen at once and the capture needs no re-posing.
"""

from __future__ import annotations

import threading

import cv2
import numpy as np

from calibration.auto import fronto_pose, make_rig, rig_board
from calibration.correspondence import decode_projector_maps
from calibration.poses import plan_poses
from calibration.preview import PreviewWorker
from calibration.response import level_image, level_plan
from calibration.sequence import Take
from calibration.validate import plane_scan
from core.errors import InputError
from core.patterns import graycode_patterns


class SimBoardSource:
    movable = True
    name = "the virtual rig"

    def __init__(self, scene: str, seed: int = 0, prefetch: bool = True, **rig_overrides: object) -> None:
        self._make = lambda: make_rig(scene, **rig_overrides)
        self.rig = self._make()
        self.board = rig_board(self.rig)
        self.suggested = plan_poses(self.board, self.rig.calibration, 40, seed=seed)
        self.k = 0
        self.patterns = graycode_patterns(self.rig.projector_size)
        self.meta = {"size": list(self.patterns.size), **self.patterns.params}
        self._prepared = None
        w, h = self.rig.projector_size
        self._white = self.rig.prepare(np.full((h, w, 3), 255, np.uint8))
        self._lock = threading.Lock()  # the rig: posed and rendered by one thread at a time
        self.rvec, self.tvec = fronto_pose(self.board, self.rig)  # the pose asked for (keys)
        self.rig.set_board_pose(self.rvec, self.tvec)
        self._applied = (self.rvec, self.tvec)  # the pose the rig shows
        self._frame_id = 0
        self.preview = PreviewWorker(self.board)
        self.preview.submit(self.live_image)
        # prefetch: a spare rig posed at suggestion `_want` by its own thread
        self._spare = None
        self._spare_at: int | None = None  # suggestion the spare shows (with its view), None = none
        self._spare_view: tuple[np.ndarray, object] | None = None
        self._spare_white = None  # the spare rig's prepared white and Gray code (prepared per rig)
        self._spare_prepared = None
        self._want = 0
        self._spare_cond = threading.Condition()
        self._closing = False
        self._prefetcher = None
        if prefetch:
            self._prefetcher = threading.Thread(target=self._prefetch_loop, name="calibration-prefetch", daemon=True)
            self._prefetcher.start()

    def _prefetch_loop(self) -> None:
        from calibration.board import detect

        try:
            spare = self._make()
        except Exception:  # no prefetch then: the key takes the ordinary path
            return
        w, h = spare.projector_size
        with self._spare_cond:
            self._spare = spare
            self._spare_white = spare.prepare(np.full((h, w, 3), 255, np.uint8))
        while True:
            with self._spare_cond:
                self._spare_cond.wait_for(lambda: self._closing or self._spare_at != self._want)
                if self._closing:
                    return
                k, spare, white = self._want, self._spare, self._spare_white
                self._spare_at, self._spare_view = None, None
            rvec, tvec = self.suggested[k % len(self.suggested)]
            try:
                spare.set_board_pose(rvec, tvec)
                image = spare.render(white)
                det = detect(self.board, image)
            except Exception:  # not prefetched: the key will take the ordinary path
                det, image = None, None
            with self._spare_cond:
                if self._want == k and self._spare is spare:
                    self._spare_at = k
                    self._spare_view = (image, det) if image is not None else None
                self._spare_cond.notify_all()

    def wait_prefetched(self, timeout_s: float = 60.0) -> bool:
        """Block until the next suggestion is prefetched (tests, benches); False on timeout."""
        with self._spare_cond:
            return self._spare_cond.wait_for(
                lambda: self._spare_at == self._want and self._spare_view is not None, timeout_s
            )

    @property
    def camera_size(self) -> tuple[int, int]:
        return self.rig.camera_size

    @property
    def projector_size(self) -> tuple[int, int]:
        return self.rig.projector_size

    @property
    def camera_gamma(self) -> float | None:
        return float(self.rig.options.camera_gamma)

    # -- posing (keys): cheap here, the re-render happens on the preview worker
    def _pose(self, rvec: np.ndarray, tvec: np.ndarray) -> None:
        self.rvec, self.tvec = np.asarray(rvec, np.float64), np.asarray(tvec, np.float64)
        rv, tv = self.rvec.copy(), self.tvec.copy()

        def job() -> np.ndarray:
            with self._lock:
                try:
                    self.rig.set_board_pose(rv, tv)
                except InputError:  # posed out of view: the board stays where it was
                    self.rvec, self.tvec = self._applied
                    raise
                self._applied = (rv, tv)
                return self.rig.render(self._white)

        self.preview.submit(job)

    def move(self, drot=(0.0, 0.0), dt=(0.0, 0.0, 0.0)) -> None:
        R, _ = cv2.Rodrigues(np.asarray(self.rvec, np.float64))
        pts = self.board.object_points().astype(np.float64)
        centre_b = (pts.min(0) + pts.max(0)) / 2
        centre = R @ centre_b + self.tvec
        dr, _ = cv2.Rodrigues(np.array([np.deg2rad(drot[0]), np.deg2rad(drot[1]), 0.0]))
        R = dr @ R
        centre = centre + np.asarray(dt, np.float64)
        self._pose(cv2.Rodrigues(R)[0].ravel(), centre - R @ centre_b)

    def flat(self) -> None:
        """The board facing the camera in the middle of the working range (colour levels, validation)."""
        self._pose(*fronto_pose(self.board, self.rig))

    def next_suggested(self) -> None:
        k = self.k
        rvec, tvec = self.suggested[k % len(self.suggested)]
        self.k += 1
        with self._spare_cond:
            ready = self._spare_at == k and self._spare_view is not None
            if ready:
                view = self._spare_view
            self._want = self.k  # the one after: prefetched next
            self._spare_cond.notify_all()
        if not ready:
            self._pose(rvec, tvec)
            return
        self.preview.wait()  # a move in flight would pose the rig being swapped out
        with self._lock, self._spare_cond:
            self.rig, self._spare = self._spare, self.rig
            self._spare_at, self._spare_view = None, None
            self._white, self._spare_white = self._spare_white, self._white
            self._prepared, self._spare_prepared = self._spare_prepared, self._prepared
            self.rvec, self.tvec = np.asarray(rvec, np.float64), np.asarray(tvec, np.float64)
            self._applied = (self.rvec, self.tvec)
            self._spare_cond.notify_all()
        self.preview.submit(lambda: view)

    # -- filming: waits for the last asked pose
    def live_image(self) -> np.ndarray:
        with self._lock:
            return self.rig.render(self._white)

    def live(self) -> np.ndarray:
        self.preview.wait()
        return self.live_image()

    def capture(self) -> Take:
        self.preview.wait()
        with self._lock:
            if self._prepared is None:
                self._prepared = [self.rig.prepare(img) for img in self.patterns.images]
            frames = [self.rig.render(p) for p in self._prepared]
        ids = list(range(self._frame_id + 1, self._frame_id + 1 + len(frames)))
        self._frame_id += len(frames)
        return Take(frames, ids, [i * 16_666_667 for i in ids])

    def levels(self) -> list[tuple[str, int, np.ndarray]]:
        """Flat colour levels per channel on the board held where it is."""
        self.preview.wait()
        with self._lock:
            return [(ch, lv, self.rig.render(level_image(self.projector_size, ch, lv))) for ch, lv in level_plan()]

    def validation_scan(self, cal) -> str:
        """Scan the board held flat and facing the camera; plane-fit residual of the result."""
        self.flat()
        frames = self.capture().frames
        column, _ = decode_projector_maps(frames, self.meta)
        scan = plane_scan(column, cal, self.rig.depth_range_mm, self.rig.ground_truth.depth)
        return (
            f"validation scan of the flat board: {scan.points} points, plane-fit residual {scan.plane_rms_mm:.3f} mm, "
            f"depth error {scan.depth_error_pct:.3f} % vs truth"
        )

    def pump(self) -> None:
        """No projector window to keep responsive: the virtual rig renders its own light."""

    def close(self) -> None:
        with self._spare_cond:
            self._closing = True
            self._spare_cond.notify_all()
        if self._prefetcher is not None:
            self._prefetcher.join(10.0)
        self.preview.close()
