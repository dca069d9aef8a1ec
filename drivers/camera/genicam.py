"""GenICam camera through harvesters (GenTL producers: GigE Vision, USB3 Vision, vendor .cti).

Options (config `rig.camera:` keys or `--camera genicam:key=value,...`):
  cti            producer(s): a .cti file, a folder, a list, or `viky` (the genicam wheel's virtual
                 producer); GENICAM_GENTL64_PATH is searched too (use_env: false to skip it)
  serial, model, device_id, index
                 which device; filters combine, `index` counts among the matches; with no
                 selection there must be exactly one device
  pixel_format   Mono8/10/12/16, RGB8, BGR8, RGBa8, Bayer*, ... (drivers/camera/pixels.py)
  exposure_us, gain_db, frame_rate
  width, height, offset_x, offset_y (or roi: [x, y, w, h])
  trigger        a line (Line1, ...) to run hardware-triggered; trigger_edge rising|falling|any;
                 trigger_selector (FrameStart). A device without TriggerMode -> UnsupportedFeatureError
  buffers        buffers announced to the producer (default 8)
  policy         newest (default: live use; older waiting buffers are skipped and counted) or
                 oldest (every frame in order, e.g. recording)

Buffers (harvesters' pitfalls): every fetch has a timeout; the pixels are converted
into a new array while the buffer is still ours and the buffer is queued back in a `finally`;
incomplete buffers are dropped and counted; frame-id gaps are counted as lost frames.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from core.errors import InputError, SlscanError
from drivers.base import CAMERAS, Frame, register
from drivers.camera import pixels
from drivers.camera.errors import (
    CameraStoppedError,
    CameraTimeoutError,
    DeviceBusyError,
    NoDeviceError,
    UnsupportedFeatureError,
)
from drivers.camera.features import NodeFeatures, apply_settings, configure_trigger
from drivers.camera.gentl import HUB, producer_paths, require_genicam
from drivers.camera.spec import as_bool

FETCH_SLICE_S = 0.05  # grab() waits in slices so stop()/close() from another thread ends it promptly
EDGES = {"rising": "RisingEdge", "falling": "FallingEdge", "any": "AnyEdge", "both": "AnyEdge"}
POLICIES = ("newest", "oldest")


@dataclass
class GrabStats:
    frames: int = 0  # frames returned by grab()
    skipped: int = 0  # complete buffers discarded by the newest-buffer policy
    lost: int = 0  # frame ids never delivered (producer overran its buffers): id gaps minus skipped
    incomplete: int = 0  # incomplete buffers dropped
    timeouts: int = 0  # grab() calls that timed out


def info_field(info: Any, key: str) -> str:
    try:
        value = getattr(info, key)
    except Exception:  # GenTL raises for information a producer does not provide
        return ""
    return "" if value is None else str(value)


def describe_info(info: Any) -> str:
    model, serial, dev_id = info_field(info, "model"), info_field(info, "serial_number"), info_field(info, "id_")
    return f"GenICam camera {model or '?'} serial={serial or '?'} ({dev_id or 'no id'})"


def select_device(
    infos: Sequence[Any],
    serial: str | None = None,
    model: str | None = None,
    device_id: str | None = None,
    index: int | None = None,
) -> Any:
    """Pick one device: filters by serial/model/id, then `index` among the matches."""
    wanted = {"serial_number": serial, "model": model, "id_": device_id}
    matches = [i for i in infos if all(v is None or info_field(i, k) == str(v) for k, v in wanted.items())]
    sel = ", ".join(f"{k}={v}" for k, v in (("serial", serial), ("model", model), ("device_id", device_id)) if v)
    sel = sel or "any"
    listing = "; ".join(describe_info(i) for i in infos) or "none"
    if index is not None:
        if not 0 <= index < len(matches):
            raise NoDeviceError(
                f"no GenICam camera index={index} among {len(matches)} matching ({sel}); found: {listing}"
            )
        return matches[index]
    if not matches:
        raise NoDeviceError(
            f"no GenICam camera matches {sel}; found: {listing} (check the cable, power and serial number)"
        )
    if len(matches) > 1:
        raise NoDeviceError(
            f"{len(matches)} GenICam cameras match {sel} ({listing}): add serial= or index= to choose one"
        )
    return matches[0]


def _opt(name: str, value: Any, kind: type) -> Any:
    if value is None:
        return None
    try:
        return kind(value)
    except (TypeError, ValueError):
        raise InputError(f"genicam camera option {name}={value!r} must be {kind.__name__}") from None


@register(CAMERAS, "genicam")
class GenICamCamera:
    def __init__(
        self,
        cti: str | Sequence[str] | None = None,
        serial: str | None = None,
        model: str | None = None,
        device_id: str | None = None,
        index: int | None = None,
        pixel_format: str | None = None,
        exposure_us: float | None = None,
        gain_db: float | None = None,
        frame_rate: float | None = None,
        width: int | None = None,
        height: int | None = None,
        offset_x: int | None = None,
        offset_y: int | None = None,
        roi: Sequence[int] | None = None,
        trigger: str | None = None,
        trigger_edge: str = "rising",
        trigger_selector: str = "FrameStart",
        buffers: int | str = 8,
        policy: str = "newest",
        use_env: bool | str = True,
        name: str | None = None,
    ) -> None:
        if roi is not None:
            if isinstance(roi, str):
                roi = roi.replace("x", ",").replace("+", ",").split(",")
            if len(roi) != 4:
                raise InputError(f"genicam camera option roi={roi!r} must be [x, y, width, height]")
            offset_x, offset_y, width, height = roi
        if policy not in POLICIES:
            raise InputError(f"genicam camera option policy={policy!r} must be one of {', '.join(POLICIES)}")
        if str(trigger_edge).lower() not in EDGES and trigger_edge not in EDGES.values():
            raise InputError(f"genicam camera option trigger_edge={trigger_edge!r} must be rising, falling or any")
        self.cti = cti
        self.use_env = as_bool("use_env", use_env)
        self.selection = {
            "serial": _opt("serial", serial, str),
            "model": _opt("model", model, str),
            "device_id": _opt("device_id", device_id, str),
            "index": _opt("index", index, int),
        }
        self.settings = {
            "pixel_format": _opt("pixel_format", pixel_format, str),
            "exposure_us": _opt("exposure_us", exposure_us, float),
            "gain_db": _opt("gain_db", gain_db, float),
            "frame_rate": _opt("frame_rate", frame_rate, float),
            "width": _opt("width", width, int),
            "height": _opt("height", height, int),
            "offset_x": _opt("offset_x", offset_x, int),
            "offset_y": _opt("offset_y", offset_y, int),
        }
        self.trigger = _opt("trigger", trigger, str)
        self.trigger_edge = EDGES.get(str(trigger_edge).lower(), str(trigger_edge))
        self.trigger_selector = str(trigger_selector)
        self.buffers = max(1, _opt("buffers", buffers, int))
        self.policy = policy
        self.name = name or "genicam"
        self.stats = GrabStats()
        self.device = "GenICam camera"  # description used in every message, set on open
        self.pixel_format = ""
        self._ia: Any = None
        self._lock = threading.Lock()  # one fetch at a time; stop()/close() wait for it
        self._stop_event = threading.Event()
        self._streaming = False
        self._last_id: int | None = None
        self._host_time: bool | None = None
        self.open()

    # -- life cycle -------------------------------------------------------------------------
    def open(self) -> None:
        """Find the producer and device, open it exclusively and apply the settings (again after close)."""
        if self._ia is not None:
            return
        require_genicam()
        from genicam.gentl import GenericException, ResourceInUseException

        files = producer_paths(self.cti, self.use_env)
        with HUB.lock:  # enumeration and open as one step: nobody re-enumerates in between
            try:
                infos = HUB.device_infos(files)
                info = select_device(infos, **self.selection)
                self.device = describe_info(info)
                ia = HUB.create(info)
            except ResourceInUseException:
                raise DeviceBusyError(
                    f"{self.device} is in use (opened by this or another program): close it there first"
                ) from None
            except GenericException as exc:
                raise DeviceBusyError(f"{self.device}: cannot open ({_msg(exc)}); check access rights") from None
            finally:
                HUB.release_if_idle()  # after a failure nothing is open: let the producers go
        self._ia = ia
        try:
            self._configure()
            ia.num_buffers = max(self.buffers, ia.min_num_buffers)
            from harvesters.core import Callback, ImageAcquirer

            camera = self

            class _CountIncomplete(Callback):  # harvesters drops incomplete buffers itself; count them
                def emit(self, context: object = None) -> None:
                    camera.stats.incomplete += 1

            ia.add_callback(ImageAcquirer.Events.INCOMPLETE_BUFFER, _CountIncomplete())
        except BaseException:
            self._ia = None
            HUB.destroy(ia)
            raise

    def start(self) -> None:
        ia = self._require_open()
        if self._streaming:
            return
        self._stop_event.clear()
        self._last_id = None
        self._host_time = None
        try:
            ia.start()
        except Exception as exc:
            raise CameraStoppedError(f"{self.device}: cannot start streaming ({_msg(exc)})") from None
        self._streaming = True

    def stop(self) -> None:
        """Stop streaming; safe from another thread while grab() waits (it ends within ~50 ms)."""
        self._stop_event.set()
        with self._lock:
            if self._ia is not None and self._streaming:
                try:
                    self._ia.stop()
                except Exception:  # a vanished device cannot be stopped; close() still releases it
                    pass
            self._streaming = False

    def close(self) -> None:
        self.stop()
        with self._lock:
            ia, self._ia = self._ia, None
            if ia is not None:
                try:
                    HUB.destroy(ia)
                except Exception:
                    pass

    def __enter__(self) -> GenICamCamera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- frames -----------------------------------------------------------------------------
    def grab(self, timeout_s: float = 1.0) -> Frame:
        """The next frame (policy `oldest`) or the newest waiting one (policy `newest`)."""
        if not self._streaming:
            raise CameraStoppedError(f"{self.device}: not streaming (call start() first)")
        from genicam.gentl import GenericException

        with self._lock:
            deadline = time.monotonic() + timeout_s
            held: list[Any] = []  # the one buffer we own at any moment; queued back in `finally`
            try:
                held.append(self._fetch(deadline))
                skipped = self._newest(held) if self.policy == "newest" else 0
                frame = self._to_frame(held[0], skipped)
            except SlscanError:
                raise
            except (GenericException, IndexError, AttributeError, RuntimeError) as exc:
                # A vanished device surfaces as GenTL errors, or as harvesters tripping over its
                # released data stream; either way the stream is gone.
                self._streaming = False
                raise CameraStoppedError(
                    f"{self.device} stopped answering ({_msg(exc)}): check cable and power, then reopen it"
                ) from None
            finally:
                if held:
                    _queue(held[0])
            return frame

    def _fetch(self, deadline: float) -> Any:
        while True:
            if self._stop_event.is_set() or self._ia is None:
                raise CameraStoppedError(f"{self.device}: stopped while waiting for a frame")
            left = deadline - time.monotonic()
            if left <= 0:
                self.stats.timeouts += 1
                raise CameraTimeoutError(
                    f"{self.device}: no frame within the timeout (is it triggered? check the trigger cable "
                    "and rate, the exposure, and the link bandwidth)"
                )
            raw = self._ia.try_fetch(timeout=min(FETCH_SLICE_S, max(left, 0.002)), is_raw=True)
            if raw is None:
                continue
            if not raw.is_complete():  # harvesters drops them already; be sure
                self.stats.incomplete += 1
                _queue(raw)
                continue
            return raw

    def _newest(self, held: list[Any]) -> int:
        """Swap held[0] for the newest complete buffer already waiting; return how many were skipped.

        Bounded by the number of buffers, so a producer faster than the drain cannot keep us here.
        """
        ds = self._ia.data_streams[0].module
        skipped = 0
        for _ in range(2 * max(1, int(getattr(self._ia, "num_buffers", self.buffers) or self.buffers))):
            try:
                waiting = ds.num_awaiting_delivery
            except Exception:
                waiting = 1  # unknown: ask once more with a short timeout
            if waiting <= 0:
                break
            nxt = self._ia.try_fetch(timeout=0.002, is_raw=True)
            if nxt is None:
                break
            if not nxt.is_complete():
                self.stats.incomplete += 1
                _queue(nxt)
                continue
            old, held[0] = held[0], nxt
            _queue(old)
            skipped += 1
            self.stats.skipped += 1
        return skipped

    def _to_frame(self, raw: Any, skipped: int = 0) -> Frame:
        w, h = _get(raw, "width") or self.settings_now["width"], _get(raw, "height") or self.settings_now["height"]
        data = raw.raw_buffer  # bytes: a copy made while the buffer is still ours
        offset = _get(raw, "image_offset") or 0
        padding = _get(raw, "padding_x") or 0
        try:
            image = pixels.to_frame(memoryview(data)[offset:], self.pixel_format, int(w), int(h), int(padding))
        except pixels.PixelFormatError as exc:
            raise UnsupportedFeatureError(f"{self.device}: {exc}") from None
        frame_id = _get(raw, "frame_id")
        if frame_id is None:
            frame_id = (self._last_id or 0) + 1
        if self._last_id is not None and frame_id > self._last_id + 1 + skipped:
            self.stats.lost += frame_id - self._last_id - 1 - skipped
        self._last_id = frame_id
        ts = None
        if self._host_time is not True:
            ts = _get(raw, "timestamp_ns") or None  # viky: NotAvailableException -> host time
            if self._host_time is None:
                self._host_time = ts is None
        if ts is None:
            ts = time.monotonic_ns()
        self.stats.frames += 1
        mosaic = pixels.camera_mosaic(self.pixel_format)
        return Frame(image=image, frame_id=int(frame_id), timestamp_ns=int(ts), mosaic=mosaic)

    # -- features ---------------------------------------------------------------------------
    def _require_open(self) -> Any:
        if self._ia is None:
            raise CameraStoppedError(f"{self.device}: closed (call open() to use it again)")
        return self._ia

    def _configure(self) -> None:
        f = NodeFeatures(self._ia.remote_device.node_map, self.device)
        self.pixel_format = apply_settings(f, self.settings)
        configure_trigger(f, self.trigger, self.trigger_edge, self.trigger_selector)
        self.settings_now = {"width": int(f.value("Width", 0)), "height": int(f.value("Height", 0))}


def _queue(raw: Any) -> None:
    try:
        raw.parent.queue_buffer(raw)
    except Exception:  # stream already stopped or device gone: the producer reclaims its buffers
        pass


def _get(raw: Any, key: str) -> Any:
    try:
        return getattr(raw, key)
    except Exception:
        return None


def _msg(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return text[:200]
