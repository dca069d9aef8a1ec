"""V4L2 camera (USB/UVC webcams, capture cards) through OpenCV's CAP_V4L2 backend.

Options: device (an index N for /dev/videoN, or a path), fourcc (e.g. MJPG, YUYV), width,
height, fps, exposure_us (manual exposure; V4L2 counts it in 100 µs units), buffers.
Every setting is read back after it is set: a camera that silently picks another value is an
UnsupportedFeatureError naming what it chose (OpenCV's set() alone does not tell).

grab(timeout_s) is bounded whatever the backend does: the blocking read runs on one worker
thread; a read that outlives the timeout stays pending and the next grab() collects it, so
reads never overlap. Frame ids count from 1 per start (OpenCV does not expose the V4L2
sequence number); timestamps are the buffer's V4L2 time (CLOCK_MONOTONIC, via
CAP_PROP_POS_MSEC) when the backend gives one, else host monotonic time at read.

No /dev/video* exists on the development machines; tests mock cv2.VideoCapture.
"""

from __future__ import annotations

import concurrent.futures
import os
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from core.errors import InputError
from drivers.base import CAMERAS, Frame, register
from drivers.camera.errors import (
    CameraStoppedError,
    CameraTimeoutError,
    DeviceBusyError,
    NoDeviceError,
    UnsupportedFeatureError,
)

DEV_DIR = Path("/dev")
VideoCapture = cv2.VideoCapture  # the driver boundary (tests replace it)


def fourcc_code(text: str) -> int:
    if len(text) != 4:
        raise InputError(f"v4l2 camera option fourcc={text!r} must be 4 characters (MJPG, YUYV, GREY, ...)")
    return cv2.VideoWriter_fourcc(*text)


def fourcc_text(code: float) -> str:
    c = int(code)
    return "".join(chr((c >> (8 * i)) & 0xFF) for i in range(4))


def device_path(device: int | str) -> tuple[int | str, Path]:
    """(what OpenCV opens, the device node) for an index or a path."""
    text = str(device).strip()
    if text.isdigit():
        return int(text), DEV_DIR / f"video{int(text)}"
    return text, Path(text)


@register(CAMERAS, "v4l2")
class V4L2Camera:
    def __init__(
        self,
        device: int | str = 0,
        fourcc: str | None = None,
        width: int | str | None = None,
        height: int | str | None = None,
        fps: float | str | None = None,
        exposure_us: float | str | None = None,
        buffers: int | str | None = None,
        name: str | None = None,
    ) -> None:
        self.source, self.path = device_path(device)
        self.device = f"V4L2 camera {self.path}"
        try:
            self.fourcc = None if fourcc is None else str(fourcc)
            self.width = None if width is None else int(width)
            self.height = None if height is None else int(height)
            self.fps = None if fps is None else float(fps)
            self.exposure_us = None if exposure_us is None else float(exposure_us)
            self.buffers = None if buffers is None else int(buffers)
        except ValueError:
            raise InputError(f"{self.device}: width/height/buffers must be integers, fps/exposure_us numbers") from None
        if self.fourcc is not None:
            fourcc_code(self.fourcc)
        self.name = name or f"v4l2:{device}"
        self._cap: Any = None
        self._pool: concurrent.futures.ThreadPoolExecutor | None = None
        self._pending: concurrent.futures.Future | None = None
        self._streaming = False
        self._count = 0
        self.open()

    def open(self) -> None:
        if self._cap is not None:
            return
        if not self.path.exists():
            raise NoDeviceError(
                f"{self.path}: no such V4L2 device (check the cable; `ls /dev/video*` or `v4l2-ctl --list-devices`)"
            )
        cap = VideoCapture(self.source, cv2.CAP_V4L2)
        if not cap.isOpened():
            cap.release()
            raise DeviceBusyError(
                f"{self.device}: cannot open (busy in another program, or no permission: check `fuser {self.path}` "
                "and membership of the video group)"
            )
        self._cap = cap
        try:
            self._configure()
        except BaseException:
            self._cap = None
            cap.release()
            raise

    def _configure(self) -> None:
        cap = self._cap
        if self.buffers is not None:
            cap.set(cv2.CAP_PROP_BUFFERSIZE, self.buffers)
        # FOURCC before the size: the size list depends on the format.
        if self.fourcc is not None:
            cap.set(cv2.CAP_PROP_FOURCC, fourcc_code(self.fourcc))
            got = fourcc_text(cap.get(cv2.CAP_PROP_FOURCC))
            if got != self.fourcc:
                raise UnsupportedFeatureError(f"{self.device}: FOURCC {self.fourcc} not accepted (camera gives {got})")
        if self.width is not None:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
        if self.height is not None:
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)
        if self.width is not None or self.height is not None:
            w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
            if (self.width or w, self.height or h) != (w, h):
                raise UnsupportedFeatureError(
                    f"{self.device}: size {self.width}x{self.height} not offered in this format (camera chose {w}x{h})"
                )
        if self.fps is not None:
            cap.set(cv2.CAP_PROP_FPS, self.fps)
            got = cap.get(cv2.CAP_PROP_FPS)
            if not got or abs(got - self.fps) > 0.05 * self.fps:
                raise UnsupportedFeatureError(f"{self.device}: {self.fps:g} fps not offered (the camera chose {got:g})")
        if self.exposure_us is not None:
            # V4L2 auto-exposure menu: 1 = manual; exposure_time_absolute is in 100 µs units.
            cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)
            units = max(1, round(self.exposure_us / 100))
            if not cap.set(cv2.CAP_PROP_EXPOSURE, units):
                raise UnsupportedFeatureError(f"{self.device}: manual exposure is not supported by this camera")
            got = cap.get(cv2.CAP_PROP_EXPOSURE)
            if abs(got - units) > max(1.0, 0.05 * units):
                raise UnsupportedFeatureError(
                    f"{self.device}: exposure {self.exposure_us:g} µs not accepted (the camera chose {got * 100:g} µs)"
                )

    def start(self) -> None:
        if self._cap is None:
            raise CameraStoppedError(f"{self.device}: closed (call open() to use it again)")
        if self._pool is None:
            self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="v4l2-read")
        self._count = 0
        self._streaming = True

    def grab(self, timeout_s: float = 1.0) -> Frame:
        if not self._streaming or self._cap is None or self._pool is None:
            raise CameraStoppedError(f"{self.device}: not streaming (call start() first)")
        if self._pending is None:
            self._pending = self._pool.submit(self._read, self._cap)
        try:
            ok, image, ts = self._pending.result(timeout=timeout_s)
        except concurrent.futures.TimeoutError:
            raise CameraTimeoutError(
                f"{self.device}: no frame within {timeout_s:g} s (check the cable, the fps and the exposure)"
            ) from None
        finally:
            if self._pending is not None and self._pending.done():
                self._pending = None
        if not ok or image is None:
            self._streaming = False
            raise CameraStoppedError(f"{self.device} stopped delivering frames (unplugged?): check it and reopen")
        self._count += 1
        return Frame(image=to_rgb(image), frame_id=self._count, timestamp_ns=ts)

    @staticmethod
    def _read(cap: Any) -> tuple[bool, np.ndarray | None, int]:
        ok, image = cap.read()
        host = time.monotonic_ns()
        try:
            ms = float(cap.get(cv2.CAP_PROP_POS_MSEC))
        except Exception:
            ms = 0.0
        return ok, image, int(ms * 1e6) if ms > 0 else host

    def stop(self) -> None:
        self._streaming = False

    def close(self) -> None:
        self._streaming = False
        cap, self._cap = self._cap, None
        pool, self._pool = self._pool, None
        self._pending = None
        if pool is not None:
            # VideoCapture is not thread-safe: release on the reader thread, after any read under way.
            if cap is not None:
                pool.submit(cap.release)
            pool.shutdown(wait=False)
        elif cap is not None:
            cap.release()

    def __enter__(self) -> V4L2Camera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def to_rgb(image: np.ndarray) -> np.ndarray:
    """OpenCV hands BGR (or grey for GREY/Y16): the program's RGB, a new array."""
    if image.ndim == 2:
        return np.repeat(image[:, :, None], 3, axis=2)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def list_v4l2_devices() -> list[dict[str, str]]:
    """The /dev/video* nodes with their driver-reported names (from sysfs; nothing is opened)."""
    out = []
    for node in sorted(DEV_DIR.glob("video*"), key=lambda p: (len(p.name), p.name)):
        name_file = Path("/sys/class/video4linux") / node.name / "name"
        try:
            label = name_file.read_text().strip()
        except OSError:
            label = ""
        out.append({"device": str(node), "name": label, "readable": str(os.access(node, os.R_OK)).lower()})
    return out
