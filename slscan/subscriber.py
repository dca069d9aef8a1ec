"""`slscan.Subscriber`: receive the depth stream of `slscan live --publish` / `slscan replay --publish`.

    for scan in slscan.Subscriber("tcp://127.0.0.1:5556", timeout_s=5):
        print(scan.sequence, scan.frame_ids, scan.depth.shape, scan.dropped)

The message format is core/depth_message.py (docs/formats.md, "Depth stream"). The stream is a ZeroMQ PUB/SUB
stream: a subscriber that falls behind loses scans instead of slowing the scanner; it sees them as gaps in
`sequence` (counted in `Subscriber.missed`). A subscriber that connects late gets the scans from then on.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from app.publisher import check_address, import_zmq
from core.depth_message import decode_message
from core.errors import InputError

RECEIVE_HWM = 4  # scans zmq keeps for this subscriber before newer ones are dropped (~1.2 MB each at 640x480)


class StreamScan:
    """One received scan. depth: H x W float32 mm, 0 = none (read-only: it is the received buffer). points, colors:
    N x 3 float32 mm and N x 3 uint8 RGB when the publisher sends them (--publish-points), else None.
    frame_ids, timestamp_ns (the camera's time of the newest frame), sequence (the publisher's scan counter: a gap
    is a scan this subscriber did not get), dropped (scans the publisher dropped before sending, so far);
    ready_ns, received_ns: host monotonic clock when the depth was ready and when it was received (same machine
    only); header: the whole header as sent."""

    def __init__(self, header: dict, depth: np.ndarray, points: Any, colors: Any, received_ns: int) -> None:
        self.header = header
        self.depth = depth
        self.points = points
        self.colors = colors
        self.frame_ids = tuple(int(i) for i in header.get("frame_ids", ()))
        self.timestamp_ns = header.get("timestamp_ns")
        self.sequence = int(header.get("sequence", -1))
        self.dropped = int(header.get("dropped", 0))
        self.calibration_sha256 = str(header.get("calibration_sha256", ""))
        self.ready_ns = int(header.get("ready_ns", 0))
        self.received_ns = received_ns

    @property
    def valid(self) -> np.ndarray:
        return self.depth > 0

    @property
    def latency_ms(self) -> float:
        """Depth ready in the scanner -> arrays here (meaningful only on the scanner's machine: one clock)."""
        return (self.received_ns - self.ready_ns) / 1e6

    def __repr__(self) -> str:
        h, w = self.depth.shape
        return f"StreamScan({w}x{h}, sequence={self.sequence}, frame_ids={self.frame_ids})"


class Subscriber:
    """Connect to a publisher at tcp://HOST:PORT (it may start later: zmq reconnects). Iterate for scans; iteration
    ends at the publisher's end message, or when no scan came for timeout_s (None: wait for ever). points: ask for
    points and colours (InputError on the first scan if the publisher does not send them)."""

    def __init__(self, address: str, *, points: bool = False, timeout_s: float | None = None) -> None:
        check_address(address, "slscan.Subscriber", bind=False)
        zmq = import_zmq("slscan.Subscriber")
        self.address = address
        self.want_points = points
        self.timeout_s = timeout_s
        self.received = 0
        self.missed = 0  # sequence gaps: scans published (or dropped by the publisher) that this subscriber lacks
        self.ended = False
        self._last_sequence: int | None = None
        self._zmq = zmq
        self._ctx = zmq.Context()
        self._sock = self._ctx.socket(zmq.SUB)
        self._sock.setsockopt(zmq.RCVHWM, RECEIVE_HWM)
        self._sock.setsockopt(zmq.LINGER, 0)
        self._sock.setsockopt(zmq.SUBSCRIBE, b"")
        try:
            self._sock.connect(address)
        except zmq.ZMQError as exc:
            self.close()
            raise InputError(f"slscan.Subscriber {address}: cannot connect: {exc.strerror}") from None

    def receive(self, timeout_s: float | None = None) -> StreamScan | None:
        """The next scan, or None after timeout_s without one (None: wait for ever) or at the end of the stream."""
        if self.ended:
            return None
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not self._sock.poll(None if wait is None else int(wait * 1000)):
                return None
            parts = self._sock.recv_multipart(copy=False)
            msg = decode_message([p.buffer for p in parts], f"slscan.Subscriber {self.address}")
            if msg.is_end:
                self.ended = True
                self._count_gap(int(msg.header.get("sequence", 0)))
                return None
            if self.want_points and msg.points is None:
                raise InputError(
                    f"slscan.Subscriber {self.address}: the publisher sends no points (start it with --publish-points)"
                )
            scan = StreamScan(msg.header, msg.depth, msg.points, msg.colors, time.monotonic_ns())
            self._count_gap(scan.sequence)
            self._last_sequence = scan.sequence
            self.received += 1
            return scan

    def _count_gap(self, sequence: int) -> None:
        if self._last_sequence is not None and sequence > self._last_sequence + 1:
            self.missed += sequence - self._last_sequence - 1

    def __iter__(self) -> Iterator[StreamScan]:
        while True:
            scan = self.receive(self.timeout_s)
            if scan is None:
                return
            yield scan

    def close(self) -> None:
        if not self._sock.closed:
            self._sock.close(0)
        if not self._ctx.closed:
            self._ctx.term()

    def __enter__(self) -> Subscriber:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
