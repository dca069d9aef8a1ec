"""A live session on a moving virtual-rig scene: each depth map is the geometry of its set's newest frame."""

from __future__ import annotations

from pathlib import Path

import yaml

from app.live_pipeline import LivePipeline, status_line
from app.session import build_session

from .conftest import depth_agreement

SIM_CONFIG = Path(__file__).resolve().parents[3] / "config" / "sim.yaml"


def moving_config(tmp_path: Path, motion_mm: float, rate_hz: float) -> Path:
    cfg = yaml.safe_load(SIM_CONFIG.read_text())
    cfg["sim"].update(
        camera_size=[320, 240], projector_size=[512, 384], effects={"motion_mm_per_frame": [motion_mm, 0, 0]}
    )
    cfg["capture"]["rate_hz"] = rate_hz
    path = tmp_path / "moving.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_a_moving_live_session_reports_the_newest_frames_depth(tmp_path):
    session = build_session(moving_config(tmp_path, motion_mm=6.0, rate_hz=2.5))
    processor = session.processor()
    camera, rig = session.sim.camera, session.sim.rig
    truths = {}  # frame id -> the rig's truth of that frame (depth, lit)
    render = camera._render

    def render_and_keep_truth(tick, pattern_tick):
        frame = render(tick, pattern_tick)
        truths[frame.frame_id] = (rig.ground_truth.depth.copy(), rig.ground_truth.lit.copy())
        return frame

    camera._render = render_and_keep_truth
    results = []
    pipe = LivePipeline(lambda: session.make_loop(timeout_s=5.0), processor, max_frames=12, on_result=results.append)
    pipe.start()
    pipe.wait()
    assert pipe.error is None
    moved = [r for r in results if r.stripes.info.get("moving", 0.0) > 0.2]
    assert len(moved) >= 4, [r.stripes.info for r in results]
    for res in moved:
        newest = res.frameset.newest.frame_id
        older = min(f.frame_id for f in res.frameset.frames)
        agree_newest, coverage = depth_agreement(res.depth, _Truth(*truths[newest]))
        agree_older, _ = depth_agreement(res.depth, _Truth(*truths[older]))
        assert agree_newest >= 0.97 and coverage >= 0.8, (agree_newest, coverage)
        assert agree_newest >= agree_older + 0.05, (agree_newest, agree_older)  # the newest frame's geometry
    fig = pipe.figures()
    assert fig["moving_share"] > 0.2
    assert "moving" in status_line(fig)


class _Truth:
    def __init__(self, depth, lit) -> None:
        self.depth, self.lit = depth, lit
