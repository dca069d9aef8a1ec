"""slscan.Scanner on the virtual rig: live scans in capture order, against the rig's ground truth."""

from __future__ import annotations

import numpy as np
import pytest

import slscan

CONFIG = {  # the virtual rig's default config, smaller
    "rig": {"camera": {"driver": "sim"}, "projector": {"driver": "sim"}, "trigger": {"driver": "sim"}},
    "sim": {"scene": "plane", "camera_size": [320, 240], "projector_size": [1024, 768]},
    "scheme": {"name": "two-shot"},
}


def test_live_scans_match_the_ground_truth_in_capture_order():
    with slscan.Scanner(CONFIG) as scanner:
        assert scanner.calibration.camera_size == (320, 240) and scanner.depth_range_mm == (600, 900)
        truth = scanner.virtual_rig.ground_truth.depth  # a still scene: every frame's truth
        scans = list(scanner.scans(6))
        fig = scanner.figures()
    assert len(scans) == 6
    newest = [max(s.frame_ids) for s in scans]
    assert newest == sorted(newest) and len(set(newest)) == 6
    assert all(sorted(s.frame_ids) == [min(s.frame_ids), min(s.frame_ids) + 1] for s in scans)  # consecutive pairs
    stamps = [s.timestamp_ns for s in scans]
    assert stamps == sorted(set(stamps))
    for scan in scans:
        err = np.abs(scan.depth - truth)[scan.valid & (truth > 0)]
        assert scan.valid.mean() > 0.9 and np.median(err) < 0.5 and np.mean(err < 2.0) > 0.99
        assert scan.points.shape == (int(scan.valid.sum()), 3)
    assert fig["frames"] >= 7 and fig["dropped"] == 0


def test_the_callback_form_and_a_closed_scanner():
    got = []
    with slscan.Scanner(CONFIG) as scanner:
        assert scanner.run(got.append, n=3) == 3
        assert scanner.run(lambda scan: False) == 1  # a callback that returns False ends it
    assert [len(s.frame_ids) for s in got] == [2, 2, 2]
    assert not scanner._pipe.running  # the with block closed the session
    with pytest.raises(slscan.InputError, match="start it first"):
        next(slscan.Scanner(CONFIG).scans(1))


def test_a_bad_config_is_one_line():
    with pytest.raises(slscan.InputError, match=r"<config mapping>: key 'scheme.name': unknown scheme 'three-shot'"):
        slscan.Scanner({**CONFIG, "scheme": {"name": "three-shot"}})
