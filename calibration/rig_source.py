"""A rig opened from the driver registries as the wizard's board source (real hardware, or the
`sim` drivers through exactly the same device protocol).

Live view: the projector shows white, the camera runs (triggered at PREVIEW_HZ when there is a
trigger) and a grabber thread keeps only the newest frame, which the preview worker checks for
the board. "Capture pose": the grabber stops and the Gray-code sequence is filmed with one
checked frame per pattern (calibration/sequence.py: the capture loop's flip record with a
trigger, stepped with settle frames and pixel checks without); then the live view resumes.
Device calls that a projector window ties to its thread (show, load) are made on the thread
that opened the rig (the wizard's UI thread); only `camera.grab` runs on the grabber.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from app.config import Config
from app.decode.mosaic import to_rgb
from calibration.board import Board, detect
from calibration.correspondence import decode_projector_maps
from calibration.preview import PreviewWorker
from calibration.response import level_image, level_plan
from calibration.sequence import Take, check_graycode, check_levels, film_stepped, film_triggered
from core.calibration import Calibration
from core.errors import DeviceError, InputError
from core.patterns import graycode_patterns
from drivers.base import CAMERAS, PROJECTORS, TRIGGERS, CameraTimeoutError

PREVIEW_HZ = 15.0  # trigger rate of the live view: enough to aim the board, light on the CPU
SETTLE_FRAMES = 3  # no trigger: frames let pass after each flip (camera pipeline latency)
VALIDATION_DEPTH_RANGE_MM = (100.0, 10000.0)  # validation scan when the config gives no working volume


def open_devices(cfg: Config) -> tuple[object, object, object | None]:
    """Camera, projector and (optional) trigger of `cfg`'s rig section, from the driver registries."""
    from app.rig_devices import make_device, rig_driver  # the live session's device construction, one rule

    cam_name, cam_opts = rig_driver(cfg, "camera", CAMERAS)
    proj_name, proj_opts = rig_driver(cfg, "projector", PROJECTORS)
    trig_name, trig_opts = rig_driver(cfg, "trigger", TRIGGERS, required=False)
    cam = make_device(cfg, "camera", CAMERAS, cam_name, cam_opts)  # type: ignore[arg-type]
    try:
        proj = make_device(cfg, "projector", PROJECTORS, proj_name, proj_opts)  # type: ignore[arg-type]
        try:
            trig = make_device(cfg, "trigger", TRIGGERS, trig_name, trig_opts) if trig_name else None
        except BaseException:
            proj.close()
            raise
    except BaseException:
        cam.close()
        raise
    return cam, proj, trig


class RigBoardSource:
    movable = False

    def __init__(
        self,
        cfg: Config,
        board: Board,
        *,
        settle: int = SETTLE_FRAMES,
        preview_hz: float = PREVIEW_HZ,
        timeout_s: float = 2.0,
        camera_gamma: float | None = None,
        devices: tuple[object, object, object | None] | None = None,
    ) -> None:
        self.cfg, self.board = cfg, board
        self.rate_hz = float(cfg.get("capture.rate_hz", 60, types=(int, float)))  # type: ignore[arg-type]
        if not 1 <= self.rate_hz <= 250:
            raise InputError(f"{cfg.path}: key 'capture.rate_hz' must be 1..250, found {self.rate_hz:g}")
        self.camera, self.projector, self.trigger = devices if devices is not None else open_devices(cfg)
        self.name = f"camera {self.camera.name}, projector {self.projector.name}" + (
            f", trigger {self.trigger.name}" if self.trigger is not None else ", no trigger"
        )
        rng = cfg.get("depth_range_mm", None)
        self.depth_range_mm = tuple(rng) if isinstance(rng, list) and len(rng) == 2 else VALIDATION_DEPTH_RANGE_MM
        self.settle, self.preview_hz, self.timeout_s = settle, min(preview_hz, self.rate_hz), timeout_s
        self.patterns = graycode_patterns(tuple(self.projector.size))
        self.meta = {"size": list(self.patterns.size), **self.patterns.params}
        self.last_note = ""  # what the last capture had to retake
        self._camera_gamma = camera_gamma
        self._grabber: threading.Thread | None = None
        self._grab_stop = threading.Event()
        self._newest: np.ndarray | None = None
        self._newest_lock = threading.Lock()
        self._camera_size: tuple[int, int] | None = None
        self.preview = PreviewWorker(board)
        try:
            self.projector.load(self.patterns.images)
            self._start_live()
            self._wait_first_frame()
        except BaseException:
            self.close()
            raise

    # -- sizes
    @property
    def camera_size(self) -> tuple[int, int]:
        assert self._camera_size is not None
        return self._camera_size

    @property
    def projector_size(self) -> tuple[int, int]:
        return tuple(self.projector.size)  # type: ignore[return-value]

    @property
    def camera_gamma(self) -> float | None:
        """--camera-gamma if given; else None: machine-vision cameras run linear (gamma off)."""
        return self._camera_gamma

    def pump(self) -> None:
        """Keep a projector window responsive between shows (the wizard's loop calls this)."""
        self.projector.poll()

    # -- live view
    def _start_live(self) -> None:
        self.projector.show(0)  # white: the board under white light
        self.camera.start()
        if self.trigger is not None:
            self.trigger.start(self.preview_hz)
        self._grab_stop.clear()
        self._grabber = threading.Thread(target=self._grab_loop, name="calibration-grabber", daemon=True)
        self._grabber.start()

    def _stop_live(self) -> None:
        if self._grabber is not None:
            self._grab_stop.set()
            self._grabber.join(self.timeout_s + 2.0)
            self._grabber = None
        if self.trigger is not None:
            self.trigger.stop()
        self.camera.stop()

    def _grab_loop(self) -> None:
        period = 1.0 / self.preview_hz
        next_t = time.monotonic()
        while not self._grab_stop.is_set():
            if self.trigger is None:  # a free-running camera: look at PREVIEW_HZ, not as fast as it goes
                wait = next_t - time.monotonic()
                if wait > 0 and self._grab_stop.wait(wait):
                    return
                next_t = max(next_t + period, time.monotonic())
            try:
                frame = self.camera.grab(0.25)
            except CameraTimeoutError:
                continue
            except Exception as exc:  # unplugged camera...: said in the window, the loop ends
                self.preview.error = f"camera {self.camera.name}: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                return
            with self._newest_lock:
                self._newest = to_rgb(frame.image, frame.mosaic)  # (a raw Bayer frame as RGB)
            if self._camera_size is None:
                h, w = frame.image.shape[:2]
                self._camera_size = (w, h)
            self.preview.submit(self._take_newest)

    def _take_newest(self) -> np.ndarray | None:
        with self._newest_lock:
            img, self._newest = self._newest, None
        return img

    def _wait_first_frame(self) -> None:
        deadline = time.monotonic() + self.timeout_s + 3.0
        while self._camera_size is None:
            if self.preview.error:
                raise DeviceError(self.preview.error)
            if time.monotonic() > deadline:
                raise DeviceError(
                    f"camera {self.camera.name}: no frame within {self.timeout_s + 3.0:.0f} s of starting the live "
                    "view (is the camera's trigger input wired to the trigger box?)"
                )
            time.sleep(0.01)

    # -- filming
    def _film(self, n: int, check) -> Take:
        """The n loaded patterns, one checked frame each (the live view stopped)."""
        if self.trigger is not None:
            take = film_triggered(
                self.camera, self.projector, self.trigger, n, self.rate_hz, check, timeout_s=self.timeout_s
            )
        else:
            self.camera.start()
            try:
                take = film_stepped(self.camera, self.projector, n, check, settle=self.settle, timeout_s=self.timeout_s)
            finally:
                self.camera.stop()
        self.last_note = take.note()
        return take

    def capture(self) -> Take:
        """The Gray-code sequence on the board as it is now; the live view resumes after."""
        self._stop_live()
        try:
            return self._film(len(self.patterns), lambda frames: check_graycode(frames, self.meta))
        finally:
            self._start_live()

    def levels(self) -> list[tuple[str, int, np.ndarray]]:
        """Flat colour levels per channel (the board held flat, filling the view)."""
        plan = level_plan()
        images = [level_image(self.projector_size, ch, lv) for ch, lv in plan]
        self._stop_live()
        try:
            self.projector.load(images)
            take = self._film(len(images), lambda frames: check_levels(frames, plan))
        finally:
            self.projector.load(self.patterns.images)
            self._start_live()
        return [(ch, lv, img) for (ch, lv), img in zip(plan, take.frames, strict=True)]

    def validation_scan(self, cal: Calibration) -> str:
        """Scan the board as held (flat, facing the camera); plane-fit residual on the board only."""
        import cv2

        from calibration.validate import plane_scan

        take = self.capture()
        white = take.frames[0]
        det = detect(self.board, white)
        if det is None:
            return "validation scan: no board in view (hold the flat board in front of the camera)"
        if tuple(cal.camera_size) != (white.shape[1], white.shape[0]):
            raise InputError(f"calibration camera_size {cal.camera_size} != the camera's frames {white.shape[1::-1]}")
        column, _ = decode_projector_maps(take.frames, self.meta)
        mask = np.zeros(column.shape, np.uint8)
        cv2.fillConvexPoly(mask, cv2.convexHull(det.corners.astype(np.float32)).astype(np.int32).reshape(-1, 2), 1)
        scan = plane_scan(column, cal, self.depth_range_mm, mask=mask.astype(bool))
        return f"validation scan of the board: {scan.points} points, plane-fit residual {scan.plane_rms_mm:.3f} mm"

    def close(self) -> None:
        """Stop the live view and close every device once, even if one of them fails."""
        if getattr(self, "_closed", False):
            return
        self._closed = True
        errors: list[BaseException] = []
        for action in (
            self._stop_live,
            lambda: self.projector.show(None),
            self.camera.close,
            lambda: self.trigger.close() if self.trigger is not None else None,
            self.projector.close,
            self.preview.close,
        ):
            try:
                action()
            except Exception as exc:
                errors.append(exc)
        if errors:
            raise errors[0]
