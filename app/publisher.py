"""`--publish tcp://HOST:PORT`: the live session's scans as a ZeroMQ PUB stream (core/depth_message.py's format).

    decode worker(s) ──offer()──► slot queue (2, oldest dropped) ──► publisher thread ──send(NOBLOCK)──► PUB socket

Invariants: offer() is O(1) and never blocks, so the decode workers never wait for the network; the socket is used
only by the publisher thread (a zmq socket is not thread-safe); the PUB socket's send high-water mark is small, and
PUB drops (never blocks) for a subscriber whose pipe is full, so a slow or stalled subscriber costs the scanner
nothing: it loses scans, which it sees as gaps in `sequence`. Every scan offered gets the next sequence number,
also one that is dropped here; `dropped` in the header counts the scans this publisher dropped itself (the queue
was full, or a slower decode worker finished an older set after a newer one was sent).
"""

from __future__ import annotations

import re
import threading
import time
from collections import deque
from typing import Any

import numpy as np

from app.live_pipeline import LiveDecoder, LiveResult
from core.depth_message import calibration_digest, encode_end, encode_scan
from core.errors import InputError

PUBLISH_HELP = "publish every scan's depth on a ZeroMQ PUB socket at tcp://HOST:PORT (slscan.Subscriber reads it)"
POINTS_HELP = "with --publish: send each scan's points and colours too"
SEND_HWM = 2  # messages queued per subscriber inside zmq: a stalled subscriber holds at most this many (+ TCP buffers)
QUEUE = 2  # scans waiting for the publisher thread: one being sent, one waiting
COPY = True  # measured at 640x480: copying the 1.2 MB depth into zmq beat zero-copy on p95 latency (2.0 vs 2.3 ms)
LINGER_MS = 200  # at close: how long the last messages (the end message) may take to leave
_ADDRESS = re.compile(r"^tcp://(?P<host>\*|[A-Za-z0-9_.\-]+|\[[0-9A-Fa-f:.]+\]):(?P<port>[0-9]{1,5})$")


def check_address(address: str, what: str = "--publish", bind: bool = True) -> tuple[str, int]:
    """tcp://HOST:PORT -> (host, port); anything else is an InputError naming `what` and the address. HOST `*` (every
    interface) only where the address is bound (bind)."""
    m = _ADDRESS.match(address or "")
    example = "tcp://127.0.0.1:5556, tcp://*:5556" if bind else "tcp://127.0.0.1:5556"
    if m is None or (m["host"] == "*" and not bind):
        raise InputError(f"{what} {address}: expected tcp://HOST:PORT (e.g. {example})")
    port = int(m["port"])
    if not 1 <= port <= 65535:
        raise InputError(f"{what} {address}: port {port} is outside 1..65535")
    return m["host"], port


def import_zmq(what: str) -> Any:
    try:
        import zmq
    except ImportError:
        raise InputError(f"{what} needs pyzmq: pip install 'slscan[stream]' (or pip install pyzmq)") from None
    return zmq


class DepthPublisher:
    """Bind a PUB socket at `address` now (so a bad address or a port in use is said before the session starts);
    attach(processor) before the first offer(); close() sends the end message and stops the thread."""

    def __init__(self, address: str, *, points: bool = False) -> None:
        check_address(address)
        zmq = import_zmq(f"--publish {address}")
        self.address = address
        self.points = points
        self._zmq = zmq
        self._ctx = zmq.Context()
        sock = self._ctx.socket(zmq.PUB)
        sock.setsockopt(zmq.SNDHWM, SEND_HWM)
        sock.setsockopt(zmq.LINGER, LINGER_MS)
        try:
            sock.bind(address)
        except zmq.ZMQError as exc:
            sock.close(0)
            self._ctx.term()
            why = "the port is in use" if exc.errno == zmq.EADDRINUSE else exc.strerror
            raise InputError(f"--publish {address}: cannot bind: {why}") from None
        self._sock = sock
        self._processor: LiveDecoder | None = None
        self._digest = ""
        self._slots: deque[tuple[int, LiveResult]] = deque()
        self._cv = threading.Condition()
        self._closing = False
        self._offered = 0  # sequence numbers given out
        self._last_index = -1  # newest set index offered: an older one is dropped (subscribers see capture order)
        self.dropped = 0  # every scan offered and not sent
        self.stale = 0  # of those: older than one already sent
        self.published = 0
        self.error: str | None = None  # the first failure to build or send a message (the scan was dropped)
        self.send_ms: deque[float] = deque(maxlen=5000)  # build + send per scan, on the publisher thread
        self._thread = threading.Thread(target=self._run, name="publisher", daemon=True)

    def attach(self, processor: LiveDecoder) -> None:
        """The decoder of a pipeline about to start (again, after the view's scheme switch): its calibration's
        digest goes in every header, its triangulator makes points. Sequence numbers go on; set indices restart."""
        with self._cv:
            self._processor = processor
            self._digest = calibration_digest(processor.calibration)
            self._last_index = -1  # a new LivePipeline counts its sets from 0 again
        if self.points:  # load (or compile) the point kernels now, not on the first scan: it dropped ~14 at 60 Hz
            w, h = processor.calibration.camera_size
            blank = np.zeros((h, w, 3), np.uint8)
            processor.triangulator.points(np.ones((h, w), np.float32), _colour_image_of([blank, blank]))
        if not self._thread.is_alive():
            self._thread.start()

    # -- the decode workers' side ----------------------------------------------------------
    def offer(self, result: LiveResult) -> None:
        """Queue a result for sending (LivePipeline's on_result, on a decode worker): never blocks."""
        with self._cv:
            seq = self._offered
            self._offered += 1
            if result.index <= self._last_index:  # (two decode workers: the older set finished second)
                self.dropped += 1
                self.stale += 1
                return
            self._last_index = result.index
            if len(self._slots) >= QUEUE:
                self._slots.popleft()
                self.dropped += 1
            self._slots.append((seq, result))
            self._cv.notify()

    # -- the publisher thread --------------------------------------------------------------
    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._slots and not self._closing:
                    self._cv.wait()
                if not self._slots:
                    return
                seq, result = self._slots.popleft()
                dropped, processor, digest = self.dropped, self._processor, self._digest  # (one pipeline's)
            t0 = time.perf_counter()
            try:
                message = self._message(seq, dropped, result, processor, digest)
                self._sock.send_multipart(message, flags=self._zmq.NOBLOCK, copy=COPY)
                self.published += 1
            except self._zmq.Again:  # (PUB drops rather than refuse; kept for a socket that refuses)
                with self._cv:
                    self.dropped += 1
            except Exception as exc:  # a bug here must not end the stream: the scan is dropped, counted, said
                with self._cv:
                    self.dropped += 1
                    self.error = self.error or f"{type(exc).__name__}: {exc}"
            self.send_ms.append((time.perf_counter() - t0) * 1e3)

    def _message(
        self, seq: int, dropped: int, result: LiveResult, processor: LiveDecoder | None, digest: str
    ) -> list[Any]:
        fs = result.frameset
        header = {
            "sequence": seq,
            "dropped": dropped,
            "set_index": result.index,
            "frame_ids": list(fs.frame_ids),
            "timestamps_ns": [int(f.timestamp_ns) for f in fs.frames],  # the camera's, per frame in pattern order
            "timestamp_ns": int(fs.newest.timestamp_ns),
            "arrival_ns": int(fs.arrival_ns),  # host monotonic clock: the set's newest frame arrived
            "ready_ns": int(result.done_ns),  # host monotonic clock: the depth map was ready
            "calibration_sha256": digest,
        }
        points = colors = None
        if self.points and processor is not None:
            cloud = processor.triangulator.points(result.depth, _colour_image(result))
            points, colors = cloud.xyz, cloud.rgb
        header["sent_ns"] = time.monotonic_ns()
        return encode_scan(header, result.depth, points, colors)

    # -- end -------------------------------------------------------------------------------
    def close(self) -> None:
        """Send what is queued and the end message (waiting at most LINGER_MS for slow subscribers); idempotent."""
        with self._cv:
            if self._closing:
                return
            self._closing = True
            self._cv.notify_all()
        if self._thread.is_alive():
            self._thread.join()
        try:
            end = encode_end({"sequence": self._offered, "dropped": self.dropped, "published": self.published})
            self._sock.send_multipart(end, flags=self._zmq.NOBLOCK)
        except self._zmq.ZMQError:
            pass
        self._sock.close(LINGER_MS)
        self._ctx.term()

    def summary(self) -> str:
        ms = np.percentile(np.asarray(self.send_ms), 50) if self.send_ms else float("nan")
        return (
            f"published {self.published} scan(s) to {self.address} ({self.dropped} dropped here, {self.stale} of them "
            "older than one sent; "
            f"send {ms:.2f} ms median)" + (f"; first failure: {self.error}" if self.error else "")
        )


def _colour_image(result: LiveResult) -> np.ndarray:
    """The texture frame before the set (the object's own colour) where there is one, else _colour_image_of."""
    if result.texture is not None:
        return result.colour_image
    return _colour_image_of([f.image for f in result.frameset.frames])


def _colour_image_of(frames: list[np.ndarray]) -> np.ndarray:
    """The points' colours: a two-shot set's frames averaged (their stripes cancel), else the first frame."""
    if len(frames) == 2:
        from app.decode.pipeline import average_frames_of

        return average_frames_of(frames[0], frames[1])
    return frames[0]


# ------------------------------------------------------------------------------------ the commands' side


def add_publish_arguments(parser: Any) -> None:
    """--publish and --publish-points (slscan live, slscan replay)."""
    parser.add_argument("--publish", metavar="tcp://HOST:PORT", help=PUBLISH_HELP)
    parser.add_argument("--publish-points", action="store_true", help=POINTS_HELP)


def open_publisher(args: Any) -> DepthPublisher | None:
    """The command's publisher (bound now, before the session starts), kept as args.publisher; None without
    --publish. The caller closes it."""
    address = getattr(args, "publish", None)
    if address is None:
        if getattr(args, "publish_points", False):
            raise InputError("--publish-points: needs --publish tcp://HOST:PORT")
        args.publisher = None
        return None
    args.publisher = DepthPublisher(address, points=bool(getattr(args, "publish_points", False)))
    return args.publisher


def result_sink(args: Any, processor: LiveDecoder) -> Any:
    """LivePipeline's on_result for the command's publisher (attached to this processor), or None."""
    publisher = getattr(args, "publisher", None)
    if publisher is None:
        return None
    publisher.attach(processor)
    return publisher.offer
