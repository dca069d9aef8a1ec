"""slscan as a library: decode frame dumps, or scan live, from your own code.

    import slscan

    dump = slscan.read_dump("rec/")                   # a frame dump: `slscan dump`, `slscan sim render`
    decoder = slscan.Decoder.for_dump(dump)           # its patterns, calibration and depth range
    for frames in dump.frame_sets():                  # RGB frames in pattern order
        scan = decoder.decode(frames)
        scan.depth, scan.points, scan.colors, scan.normals

    with slscan.Scanner() as scanner:                 # live, on the virtual rig by default
        for scan in scanner.scans(10):
            print(scan.frame_ids, scan.timestamp_ns, scan.valid.sum())

    for scan in slscan.Subscriber("tcp://127.0.0.1:5556"):   # `slscan live --publish tcp://127.0.0.1:5556`
        print(scan.sequence, scan.frame_ids, scan.depth.shape)

Units and frames: millimetres; the camera frame (x right, y down, z forward); depth 0 = none
(docs/formats.md). Errors a user can fix are slscan.SlscanError (InputError: a bad argument, file or frame;
DeviceError: a device), with a one-line message naming what to fix.
"""

from slscan import _layers  # noqa: F401  (first: slscan's own app/core/drivers/calibration, whatever cwd holds)

__version__ = "0.1.0"

from core.calibration import Calibration
from core.errors import DeviceError, InputError, SlscanError
from core.pattern_export import read_patterns
from core.patterns import PatternSet, make_patterns
from slscan.decoder import Decoder
from slscan.dump import Dump, FrameSets, read_dump
from slscan.frameset import FrameSet
from slscan.scan import Scan
from slscan.scanner import Scanner
from slscan.subscriber import StreamScan, Subscriber

__all__ = [
    "Calibration",
    "Decoder",
    "DeviceError",
    "Dump",
    "FrameSet",
    "FrameSets",
    "InputError",
    "PatternSet",
    "Scan",
    "Scanner",
    "SlscanError",
    "StreamScan",
    "Subscriber",
    "__version__",
    "make_patterns",
    "read_dump",
    "read_patterns",
]
