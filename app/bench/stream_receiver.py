"""The subscriber process of `slscan bench --live`'s "published" row: `python -m app.bench.stream_receiver ADDRESS`.

Prints "ready" once connected, receives until the stream's end message (or 30 s without a scan), and prints one
JSON line: scans received, sequence gaps, end seen, and the latency of each scan from the depth being ready in the
scanner to the arrays being here (one machine: the header's ready_ns and this process's time.monotonic_ns share
the clock). It reads with zmq and core/depth_message.py directly: app/ does not import slscan.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from core.depth_message import decode_message


def main(argv: list[str]) -> int:
    import zmq

    ctx = zmq.Context()
    sock = ctx.socket(zmq.SUB)
    sock.setsockopt(zmq.RCVHWM, 4)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.SUBSCRIBE, b"")
    sock.connect(argv[0])
    print("ready", flush=True)
    latency, last, missed, ended, first = [], None, 0, False, True
    while sock.poll(120_000 if first else 30_000):
        first = False
        msg = decode_message([p.buffer for p in sock.recv_multipart(copy=False)])
        now = time.monotonic_ns()
        seq = int(msg.header["sequence"])
        missed += 0 if last is None else max(0, seq - last - 1)
        if msg.is_end:
            ended = True
            break
        last = seq
        latency.append((now - int(msg.header["ready_ns"])) / 1e6)
    sock.close(0)
    ctx.term()
    lat = np.asarray(latency) if latency else np.full(1, np.nan)
    out = {"received": len(latency), "missed": missed, "ended": ended}
    out |= {"latency_p50_ms": float(np.median(lat)), "latency_p95_ms": float(np.percentile(lat, 95))}
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
