"""The live pipeline: acquisition, decoding and sinks on separate threads, joined by bounded queues.

    acquisition thread ──► decode queue (bounded) ──► decode worker(s) ──► results ──► sinks
      CaptureLoop.step()     full: drop the OLDEST set,     FrameSet -> StripeMap    view: newest only,
      recorder.put(frame)    counted as stale_sets          -> depth (triangulate)   older = stale_results

Stale-data policy: the decoder works on the newest sets; a set that waited
while a newer one arrived is dropped and counted. The recorder is fed by the acquisition thread
directly and never drops silently (app/recorder.py). Every stage is timed (ms) and the latency of
each depth map is measured from the host arrival of its newest frame to the end of triangulation.

Threads, not processes: the decode kernels are numba `nogil` and the virtual camera renders with
OpenCV, both release the GIL; `slscan bench --live` measures whether that keeps up.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from app.capture import CaptureLoop, CaptureStats, FrameSet
from app.decode.mosaic import to_rgb
from app.decode.stripemap import StripeMap
from app.recorder import Recorder, lower_thread_priority
from core.calibration import Calibration
from core.errors import SlscanError
from core.patterns import PatternSet
from drivers.base import Frame

# Decode threads by default: the compiled kernels release the GIL, so two threads use two cores
# (measured on the virtual rig at 640x480: 2 threads gave 40.7 depth maps/s with capture at 59.6 frames/s).
DECODE_WORKERS = max(1, min(2, os.cpu_count() or 1))
WORKERS_HELP = f"decode threads (default {DECODE_WORKERS}: up to 2, as many as the cores)"

# A headless run's last scan is saved: a texture frame is asked for this many frames before the end, so that the
# sets after it (from the fourth frame on: the pixel check restarts after the break) colour the saved cloud.
TEXTURE_LEAD = 12

# ------------------------------------------------------------------------------------ decode stage


class LiveDecoder:
    """FrameSet -> (StripeMap, depth): the scheme's FrameSetDecoder, built once. Decoding and triangulation are timed
    apart, except where the two-shot decoder triangulates row by row in its own pass (triangulates_in_decode)."""

    def __init__(
        self,
        patterns: PatternSet,
        calibration: Calibration,
        depth_range_mm: tuple[float, float] | None,
        segmentation: str | None = None,
        motion: str = "auto",
        mosaic: str | None = None,
    ) -> None:
        """mosaic: a single-chip camera's Bayer mosaic; its raw frames are reconstructed to RGB by the decoder."""
        from app.decode.pipeline import FrameSetDecoder

        self.scheme = patterns.scheme
        self.patterns = patterns
        self.calibration = calibration
        meta = {**patterns.params, "scheme": patterns.scheme, "size": list(patterns.size)}
        self.frameset_decoder = FrameSetDecoder(
            patterns.scheme, meta, calibration, depth_range_mm, segmentation, motion, mosaic
        )
        self.mosaic = self.frameset_decoder.mosaic
        self.triangulator = self.frameset_decoder.triangulator
        self.decoder = self.frameset_decoder.decoder
        # (a mirrored rig's decoder leaves the depth map to a separate pass: TwoShotDecoder.decode_depth)
        self.triangulates_in_decode = (
            self.frameset_decoder.kind.depth_in_decode
            and self.triangulator.moebius_geometry is not None
            and not self.decoder.mirrored
        )

    def warm_up(
        self, dtype: np.dtype | type = np.uint8, announce: Callable[[], None] | None = None, after_s: float = 1.0
    ) -> float:
        """Decode one blank frame set of the calibration's camera size and this dtype, so that the kernels are
        compiled (numba's cache is empty on a first run, and after the kernels' sources change) or loaded from the
        cache now, not on the first live set: compiling holds the GIL for ~45 s, which starved the capture thread (a
        cold `slscan live` took 4 frames/s and gave its first depth map after 69 s). Gray code decodes with numpy:
        only its triangulation is compiled, so only that runs (a blank 1920x1080 set took ~1 s to decode).
        announce() is called if it takes longer than after_s (from a timer thread). Returns the seconds it took."""
        w, h = self.calibration.camera_size
        timer = threading.Timer(after_s, announce) if announce is not None else None
        t0 = time.perf_counter()
        if timer is not None:
            timer.daemon = True
            timer.start()
        try:
            if not self.frameset_decoder.kind.compiled:  # numpy decoding: only the triangulation compiles
                self.triangulator.depth(np.full((h, w), np.nan, np.float32))
            else:
                blank = np.zeros((h, w) if self.mosaic is not None else (h, w, 3), dtype)
                # (with motion the repair of a pair's older frame compiles too: app/decode/motion.py)
                previous = blank if self.frameset_decoder.motion is not None else None
                self.decode_depth((blank,) * len(self.patterns), len(self.patterns) - 1, previous)
        finally:
            if timer is not None:
                timer.cancel()
        return time.perf_counter() - t0

    def decode_depth(
        self, images: tuple[np.ndarray, ...], newest: int | None = None, previous: np.ndarray | None = None
    ) -> tuple[StripeMap, np.ndarray, float]:
        """images[p] saw pattern p: the stripe map, the depth map and the time of a separate triangulation pass in
        ms (0 where the two-shot decoder triangulates row by row in its own pass: FrameSetDecoder.stripes_and_depth).
        newest, previous: the index of the frame taken last and the frame before the set, for motion (two-shot)."""
        if self.triangulates_in_decode:
            stripes, depth = self.frameset_decoder.stripes_and_depth(list(images), newest, previous)
            return stripes, depth, 0.0
        stripes = self.frameset_decoder.stripes(list(images), newest, previous)
        t0 = time.perf_counter()
        depth = self.depth(stripes)
        return stripes, depth, (time.perf_counter() - t0) * 1e3

    def decode(self, images: tuple[np.ndarray, ...]) -> StripeMap:
        """images[p] saw pattern p (the order in time does not matter to the decoders)."""
        return self.frameset_decoder.stripes(images)

    def depth(self, stripes: StripeMap) -> np.ndarray:
        return self.triangulator.depth(stripes.column)


# ------------------------------------------------------------------------------------ results


@dataclass
class LiveResult:
    """One decoded frame set."""

    index: int  # sequence number of the set (in acquisition order)
    frameset: FrameSet
    stripes: StripeMap
    depth: np.ndarray  # float32 mm, 0 = none
    decode_ms: float
    triangulate_ms: float
    done_ns: int
    texture: Frame | None = None  # the newest white-light texture frame before the set, if any (colours the cloud)

    @property
    def latency_ms(self) -> float:
        return (self.done_ns - self.frameset.arrival_ns) / 1e6

    @property
    def image(self) -> np.ndarray:
        """The newest camera frame of the set as RGB (for display and point colours; a raw Bayer frame
        reconstructed, app/decode/mosaic.py)."""
        newest = self.frameset.newest
        return to_rgb(newest.image, newest.mosaic)

    @property
    def colour_image(self) -> np.ndarray:
        """The RGB image that colours the points: the texture frame (the object's own colour under white light), else
        the newest frame of the set."""
        if self.texture is None:
            return self.image
        return to_rgb(self.texture.image, self.texture.mosaic)


@dataclass
class PipelineStats:
    started_ns: int = 0
    stopped_ns: int = 0
    sets_in: int = 0  # sets the capture loop completed
    stale_sets: int = 0  # dropped before decoding: a newer set arrived first
    decoded: int = 0
    failed: int = 0  # sets the decoder refused (error message kept)
    stale_results: int = 0  # decoded but replaced before a sink showed them
    recorded: int = 0
    grab_ms: deque = field(default_factory=lambda: deque(maxlen=5000))  # show + grab + check per frame
    decode_ms: deque = field(default_factory=lambda: deque(maxlen=5000))
    triangulate_ms: deque = field(default_factory=lambda: deque(maxlen=5000))
    latency_ms: deque = field(default_factory=lambda: deque(maxlen=5000))
    moving: deque = field(default_factory=lambda: deque(maxlen=120))  # share of pixels decoded as moving, per set
    frame_arrivals: deque = field(default_factory=lambda: deque(maxlen=120))  # ns, for a rolling rate
    result_times: deque = field(default_factory=lambda: deque(maxlen=120))
    # CPU seconds each thread used (thread name -> s), filled as the threads end: where the time goes.
    # "acquisition" includes the camera driver's grab (the virtual rig renders its frames there).
    cpu_s: dict = field(default_factory=dict)

    def elapsed_s(self, now_ns: int | None = None) -> float:
        end = self.stopped_ns or now_ns or time.monotonic_ns()
        return max(1e-9, (end - self.started_ns) / 1e9) if self.started_ns else 0.0


def _rate(times: deque) -> float:
    t = list(times)
    return (len(t) - 1) / ((t[-1] - t[0]) / 1e9) if len(t) > 2 and t[-1] > t[0] else 0.0


def percentile(values, q: float) -> float:
    v = np.asarray(list(values), np.float64)
    return float(np.percentile(v, q)) if v.size else float("nan")


# ------------------------------------------------------------------------------------ the pipeline


class LivePipeline:
    """Run a capture loop and decode its sets on worker threads; results go to `on_result`.

    make_loop: builds the CaptureLoop *on the acquisition thread* (a pyglet projector window must
    be used by the thread that opened it). max_frames: stop after that many camera frames; max_recorded:
    after that many frames handed to the recorder (confirmed frames only: refused ones are not counted).
    on_result: called on a worker thread with every LiveResult (keep it short: store, don't draw).
    processor None: no decoding (recording only).
    """

    def __init__(
        self,
        make_loop: Callable[[], CaptureLoop],
        processor: LiveDecoder | None,
        *,
        workers: int = 1,
        queue_sets: int = 1,
        max_frames: int | None = None,
        max_recorded: int | None = None,
        recorder: Recorder | None = None,
        on_result: Callable[[LiveResult], None] | None = None,
        on_frame: Callable[[Frame], None] | None = None,
        texture_at_end: bool = False,
    ) -> None:
        self.make_loop = make_loop
        self.processor = processor
        self.workers = max(1, workers)
        self.max_frames = max_frames
        self.max_recorded = max_recorded
        self.recorder = recorder
        self.on_result = on_result
        self.on_frame = on_frame
        self.stats = PipelineStats()
        self.capture: CaptureStats = CaptureStats()
        self.error: str | None = None  # why the session stopped early (device fault), for the operator
        self.stop_reason: str | None = None  # a clean early stop the operator asked for
        self.decode_error: str | None = None
        self.latest: LiveResult | None = None
        self.latest_frame: Frame | None = None
        # the newest white-light texture frame: it colours the sets that complete after it (LiveResult.texture)
        self.latest_texture: Frame | None = None
        self.texture_at_end = texture_at_end  # with max_frames: a texture frame TEXTURE_LEAD frames before the end
        self._sets: deque[tuple[int, FrameSet, Frame | None]] = deque()
        self._queue_sets = max(1, queue_sets)
        self._cv = threading.Condition()
        self._stop = threading.Event()
        self._acq_done = threading.Event()
        self._ready = threading.Event()
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._set_index = 0
        self._unshown = 0
        self._has_view = False
        self.loop: CaptureLoop | None = None

    # -- control ---------------------------------------------------------------------------
    def start(self) -> None:
        self.stats.started_ns = time.monotonic_ns()
        acq = threading.Thread(target=self._acquire, name="acquisition", daemon=True)
        n_workers = self.workers if self.processor is not None else 0
        self._threads = [acq] + [
            threading.Thread(target=self._decode_worker, name=f"decode-{i}", daemon=True) for i in range(n_workers)
        ]
        for t in self._threads:
            t.start()
        self._ready.wait(30.0)

    def stop(self) -> None:
        """Ask every stage to finish (returns at once; `join` waits)."""
        self._stop.set()
        with self._cv:
            self._cv.notify_all()

    def request_texture(self) -> bool:
        """Ask the capture loop for a texture frame at its next tick; False before the loop runs, or without a
        projector (a replay takes the texture frames its dump recorded)."""
        loop = self.loop
        if loop is None or loop.projector is None:
            return False
        loop.request_texture()
        return True

    def set_recorder(self, recorder: Recorder | None) -> Recorder | None:
        """Start (a Recorder) or stop (None) recording; returns the previous recorder (to close)."""
        with self._lock:
            old, self.recorder = self.recorder, recorder
        return old

    def join(self, timeout_s: float | None = None) -> None:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        for t in self._threads:
            t.join(None if deadline is None else max(0.0, deadline - time.monotonic()))
        if not self.stats.stopped_ns:
            self.stats.stopped_ns = time.monotonic_ns()

    def wait(self, poll_s: float = 0.2) -> None:
        """Block until the session ends (frames done, stop(), or a device fault); Ctrl-C stops it cleanly."""
        try:
            while not self._acq_done.wait(poll_s):
                pass
        except KeyboardInterrupt:
            self.stop()
            self.join()
            raise
        self.join()

    @property
    def running(self) -> bool:
        return not self._acq_done.is_set()

    # -- acquisition -----------------------------------------------------------------------
    def _acquire(self) -> None:
        loop = None
        cpu0 = time.thread_time()
        try:
            loop = self.make_loop()
            self.loop = loop
            self.capture = loop.stats
            loop.start()
            self._ready.set()
            n = 0
            while not self._stop.is_set() and (self.max_frames is None or n < self.max_frames):
                if loop.stop_requested:
                    self.stop_reason = "the projector window was closed"
                    break
                t0 = time.perf_counter()
                if self.texture_at_end and self.max_frames is not None and n == self.max_frames - TEXTURE_LEAD:
                    loop.request_texture()
                ev = loop.step()
                self.stats.grab_ms.append((time.perf_counter() - t0) * 1e3)
                self.stats.frame_arrivals.append(ev.arrival_ns)
                n += 1
                if ev.texture is not None:
                    self.latest_texture = ev.texture
                self.latest_frame = ev.raw
                if self.on_frame is not None:
                    self.on_frame(ev.raw)
                if ev.confirmed:
                    with self._lock:
                        rec = self.recorder
                    # Only frames whose tag is certain are recorded: a dump is decoded offline
                    # without these checks. Tagged frames never confirmed are counted (stats).
                    for f in ev.confirmed if rec is not None else ():
                        if self.max_recorded is not None and self.stats.recorded >= self.max_recorded:
                            break
                        if rec.put(f):
                            self.stats.recorded += 1
                if ev.frameset is not None and self.processor is not None:
                    self._push_set(ev.frameset)
                if self.max_recorded is not None and self.stats.recorded >= self.max_recorded:
                    break
        except SlscanError as exc:
            if type(exc).__name__ != "EndOfDumpError":  # a replay that reached its end is a normal end
                self.error = str(exc)
        except Exception as exc:  # a driver bug must still end the session cleanly, and say what
            self.error = f"{type(exc).__name__}: {exc}"
        finally:
            if loop is not None:
                try:
                    loop.close()
                except Exception as exc:
                    self.error = self.error or f"closing the devices failed: {exc}"
                if loop.projector_cpu_s:
                    self.stats.cpu_s["projector"] = loop.projector_cpu_s
            self.stats.cpu_s["acquisition"] = time.thread_time() - cpu0
            self._ready.set()
            self._acq_done.set()
            with self._cv:
                self._cv.notify_all()

    def _push_set(self, fs: FrameSet) -> None:
        with self._cv:
            self.stats.sets_in += 1
            if len(self._sets) >= self._queue_sets:
                self._sets.popleft()
                self.stats.stale_sets += 1
            self._sets.append((self._set_index, fs, self.latest_texture))
            self._set_index += 1
            self._cv.notify()

    # -- decoding --------------------------------------------------------------------------
    def _decode_worker(self) -> None:
        # Capture first, then the recorder, then decoding: a late depth map is only stale, a frame
        # the capture thread misses is gone (and breaks two pairs).
        lower_thread_priority(2)
        cpu0 = time.thread_time()
        try:
            self._decode_loop()
        finally:
            self.stats.cpu_s[threading.current_thread().name] = time.thread_time() - cpu0

    def _decode_loop(self) -> None:
        while True:
            with self._cv:
                while not self._sets and not self._acq_done.is_set() and not self._stop.is_set():
                    self._cv.wait(0.5)
                if not self._sets:
                    return
                if self._stop.is_set() and not self._acq_done.is_set():
                    self._sets.clear()
                    return
                index, fs, texture = self._sets.popleft()
            try:
                t0 = time.perf_counter()
                previous = fs.previous.image if fs.previous is not None else None
                images = tuple(f.image for f in fs.frames)
                stripes, depth, tri_ms = self.processor.decode_depth(images, fs.newest_index, previous)
                t2 = time.perf_counter()
                t1 = t2 - tri_ms / 1e3  # (decode_ms includes the triangulation done in the decoder's pass)
            except Exception as exc:  # one bad set (or a decoder bug) must not kill the worker; counted, kept
                self.stats.failed += 1
                self.decode_error = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                continue
            res = LiveResult(index, fs, stripes, depth, (t1 - t0) * 1e3, (t2 - t1) * 1e3, time.monotonic_ns(), texture)
            st = self.stats
            with self._lock:
                st.decoded += 1
                st.decode_ms.append(res.decode_ms)
                st.triangulate_ms.append(res.triangulate_ms)
                st.latency_ms.append(res.latency_ms)
                st.moving.append(float(stripes.info.get("moving", 0.0)))
                st.result_times.append(res.done_ns)
                # Stale results exist only for a sink that shows them (the view); headless keeps the newest.
                if self.latest is None or res.index > self.latest.index:
                    if self._unshown and self._has_view:
                        st.stale_results += 1
                    self.latest = res
                    self._unshown = 1
                elif self._has_view:
                    st.stale_results += 1  # a slower worker finished an older set: never shown
            if self.on_result is not None:
                self.on_result(res)

    def take_latest(self) -> LiveResult | None:
        """The newest result not yet taken by a sink (the view calls this once per redraw)."""
        with self._lock:
            self._has_view = True
            if not self._unshown:
                return None
            self._unshown = 0
            return self.latest

    # -- figures ---------------------------------------------------------------------------
    def figures(self) -> dict:
        """The numbers the status line and the headless run print."""
        st, cap = self.stats, self.capture
        elapsed = st.elapsed_s()
        running = self.running
        return {
            "frames": cap.frames,
            "frames_per_s": _rate(st.frame_arrivals) if running else cap.frames / elapsed if elapsed else 0.0,
            "depth_maps": st.decoded,
            "depth_per_s": _rate(st.result_times) if running else st.decoded / elapsed if elapsed else 0.0,
            "latency_ms_p50": percentile(st.latency_ms, 50),
            "latency_ms_p95": percentile(st.latency_ms, 95),
            "decode_ms_p50": percentile(st.decode_ms, 50),
            "moving_share": float(np.mean(st.moving)) if st.moving else 0.0,  # over the last sets decoded
            "triangulated_in_decode": self.processor is not None and self.processor.triangulates_in_decode,
            "triangulate_ms_p50": percentile(st.triangulate_ms, 50),
            "grab_ms_p50": percentile(st.grab_ms, 50),
            "dropped": cap.dropped,
            "refused": cap.refused,  # frames refused by the tag checks (never paired)
            "stale_sets": st.stale_sets,
            "stale_results": st.stale_results,
            "recorded": st.recorded,
            "textures": cap.textures,
            "capture": cap.as_dict(),
            "cpu_ms_per_frame": {k: 1e3 * v / max(cap.frames, 1) for k, v in sorted(st.cpu_s.items())},
            "elapsed_s": elapsed,
        }


def status_line(fig: dict, recording: str = "") -> str:
    """One line for the view and the terminal."""
    lat = fig["latency_ms_p95"]
    lat_s = "-" if lat != lat else f"{lat:.0f} ms"
    return (
        f"{fig['frames_per_s']:5.1f} frames/s  {fig['depth_per_s']:5.1f} depth/s  latency p95 {lat_s}  "
        f"moving {100 * fig.get('moving_share', 0.0):3.0f} %  "
        f"dropped {fig['dropped']}  refused {fig['refused']}  stale {fig['stale_sets'] + fig['stale_results']}"
        + (f"  {recording}" if recording else "")
    )
