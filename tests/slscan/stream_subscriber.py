"""A subscriber process for the depth-stream tests: `python stream_subscriber.py ADDRESS OUT.npz [STALL_S] [points]`.

Connects, prints "ready", waits for the first scan, then stays away for STALL_S seconds (a stalled subscriber: it
reads nothing meanwhile, while the session is publishing, however long the session took to start), then reads
until the stream's end message (or 15 s without a scan) and saves what it received to OUT.npz.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the worktree's slscan, whatever cwd is

import numpy as np

import slscan


def main() -> None:
    address, out = sys.argv[1], sys.argv[2]
    stall_s = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    points = len(sys.argv) > 4 and sys.argv[4] == "points"
    rows: list[tuple] = []
    last = None
    with slscan.Subscriber(address, points=points, timeout_s=15.0) as sub:
        print("ready", flush=True)
        first = sub.receive(timeout_s=120.0)  # the session compiles or loads its decoder first
        time.sleep(stall_s)
        scans = [first] if first is not None else []
        for scan in (*scans, *sub) if scans else ():
            rows.append((scan.sequence, max(scan.frame_ids), min(scan.frame_ids), scan.dropped, scan.latency_ms))
            if points:  # each point's z is its pixel's depth, in row-major order
                assert np.array_equal(scan.points[:, 2], scan.depth[scan.valid]), "points do not match the depth"
                assert scan.colors.shape == scan.points.shape and scan.colors.dtype == np.uint8
            last = scan
        np.savez(
            out,
            rows=np.array(rows, np.float64).reshape(-1, 5),
            depth=last.depth if last is not None else np.zeros((0, 0), np.float32),
            digest=last.calibration_sha256 if last is not None else "",
            missed=sub.missed,
            ended=sub.ended,
        )


if __name__ == "__main__":
    main()
