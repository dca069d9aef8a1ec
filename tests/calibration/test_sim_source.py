"""The virtual rig's board source: keys return at once, the view follows from the preview worker, and
the prefetched "next pose" swaps in a rig already posed there: what is shown is what is filmed."""

from __future__ import annotations

import numpy as np

from calibration.board import detect
from calibration.sim_source import SimBoardSource


def test_next_pose_is_prefetched_and_filmed_where_shown():
    src = SimBoardSource("checkerboard", seed=2, supersample=2)
    try:
        assert src.wait_prefetched()
        first = src.rig
        src.next_suggested()
        view = src.preview.wait()
        assert src.rig is not first  # the prefetched rig was swapped in, nothing re-posed
        rvec, tvec = src.suggested[0]
        assert np.allclose(src.rig.board.rvec, rvec) and np.allclose(src.rig.board.tvec, tvec)
        true = src.rig.board_corners_image()
        assert view.detection is not None and np.median(np.abs(view.detection.corners - true[view.detection.ids])) < 0.3
        take = src.capture()
        det = detect(src.board, take.frames[0])
        assert det is not None and np.median(np.abs(det.corners - true[det.ids])) < 0.3
        # an arrow key poses the current rig on the worker; the capture waits for it
        src.move((5, 0))
        take = src.capture()
        assert not np.allclose(src.rig.board.rvec, rvec)
        det = detect(src.board, take.frames[0])
        true = src.rig.board_corners_image()
        assert det is not None and np.median(np.abs(det.corners - true[det.ids])) < 0.3
        # the next suggestion is prefetched on the rig swapped out
        assert src.wait_prefetched()
        src.next_suggested()
        src.preview.wait()
        assert src.rig is first and np.allclose(src.rig.board.rvec, src.suggested[1][0])
    finally:
        src.close()
