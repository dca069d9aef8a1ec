"""The live pipeline on the virtual rig: depth maps against the rig's ground truth, and injected
faults (drops, duplicates, swaps, late flips) that never produce a mispaired depth map."""

from __future__ import annotations

import numpy as np

from app.live_pipeline import LivePipeline
from app.session import build_session

from .conftest import SMALL, depth_agreement


def run_pipeline(session, processor, frames: int, **kw):
    results = []
    pipe = LivePipeline(
        lambda: session.make_loop(timeout_s=3.0), processor, max_frames=frames, on_result=results.append, **kw
    )
    pipe.start()
    pipe.wait()
    return pipe, results


def assert_sets_saw_their_patterns(session, results) -> int:
    """Every decoded set: frame p really saw pattern p (the sim camera's truth), frames consecutive."""
    cam = session.sim.camera
    for res in results:
        ids = res.frameset.frame_ids
        assert [cam.truth(i) for i in ids] == list(range(len(ids))), f"mispaired set {ids}"
        assert sorted(ids) == list(range(min(ids), min(ids) + len(ids)))
    return len(results)


def test_headless_live_run_matches_ground_truth(sim_session):
    session, processor = sim_session
    pipe, results = run_pipeline(session, processor, frames=40)
    assert pipe.error is None
    fig = pipe.figures()
    assert fig["frames"] == 40 and fig["depth_maps"] >= 1
    assert assert_sets_saw_their_patterns(session, results) == fig["depth_maps"]
    gt = session.sim.rig.ground_truth
    correct, coverage = depth_agreement(pipe.latest.depth, gt)
    assert correct > 0.95, correct
    both = (pipe.latest.depth > 0) & (gt.depth > 0)
    assert np.median(np.abs(pipe.latest.depth[both] - gt.depth[both])) < 0.5
    # the tags matter: the same two frames taken in the wrong order decode to wrong depth
    f0, f1 = (f.image for f in pipe.latest.frameset.frames)
    # the live loop takes the decoder's own triangulation pass: the depths of the separate one
    assert np.array_equal(pipe.latest.depth, processor.depth(processor.decode((f0, f1))))
    assert fig["triangulate_ms_p50"] == 0.0 and fig["triangulated_in_decode"]
    wrong = processor.depth(processor.decode((f1, f0)))
    assert depth_agreement(wrong, gt)[0] < 0.5
    assert coverage > 0.25, coverage  # coverage targets belong to the decoder and its bench
    # each frame is tagged from the flip log: tags alternate with the trigger count
    assert pipe.capture.tagged + pipe.capture.refused == pipe.capture.frames


def test_injected_faults_are_counted_and_never_decoded_as_pairs(sim_session):
    faults = [
        {"kind": "drop", "at": [8, 30]},
        {"kind": "duplicate", "at": [12, 41]},
        {"kind": "swap", "at": [18, 50]},
        {"kind": "late_flip", "at": [24, 56]},
    ]
    session = build_session(None, sim_overrides={**SMALL, "faults": faults})
    processor = sim_session[1]  # same rig geometry and patterns: the same decoder
    pipe, results = run_pipeline(session, processor, frames=70)
    cap = pipe.capture
    assert pipe.error is None
    assert cap.dropped >= 2
    assert cap.duplicates >= 2
    assert cap.out_of_order >= 2
    assert cap.mistagged >= 2  # the late flips, seen in the pixels
    assert assert_sets_saw_their_patterns(session, results) >= 10


def test_camera_that_disappears_stops_the_session_with_a_message(tmp_path):
    from app.session import open_recorder
    from core.dump import read_dump

    session = build_session(None, sim_overrides={**SMALL, "faults": [{"kind": "disappear", "at": [15]}]})
    rec = open_recorder(session, tmp_path / "rec")
    pipe = LivePipeline(lambda: session.make_loop(timeout_s=1.0), None, max_frames=1000, recorder=rec)
    pipe.start()
    pipe.wait()
    rec.close()
    assert "disappeared" in pipe.error
    dump = read_dump(tmp_path / "rec")  # finalised, readable
    assert 5 <= len(dump.frames) <= 14
    assert np.array_equal(dump.load_frame(0).shape, (240, 320, 3))


def test_one_shot_and_graycode_run_through_the_same_loop():
    for scheme, steps in (("one-shot", 12), ("graycode", 0)):
        session = build_session(None, scheme=scheme, sim_overrides=SMALL)
        n = len(session.patterns)
        # Gray-code sets need the pixel check's cycle before them and a whole cycle without a break:
        # on a loaded machine a missed tick restarts that, so allow a few cycles and stop at the first set.
        steps = steps or 12 * n
        cam = session.sim.camera
        loop = session.make_loop(timeout_s=3.0)
        sets = []
        try:
            loop.start()
            for _ in range(steps):
                ev = loop.step()
                if ev.frame is not None:
                    assert cam.truth(ev.frame.frame_id) == ev.frame.pattern
                if ev.frameset is not None:
                    sets.append(ev.frameset)
                    if scheme == "graycode":
                        break
        finally:
            loop.close()
        assert sets, (scheme, loop.stats)
        for fs in sets:
            assert [cam.truth(i) for i in fs.frame_ids] == list(range(n))
        if scheme == "one-shot":
            assert len(sets) == loop.stats.tagged


def test_trigger_reset_mid_session_resyncs_and_never_mispairs():
    """The virtual trigger reboots at tick 40 (counter back to 0): the loop restarts it, re-makes its
    schedule, refuses the frames in between, and pairs again. Stepped mode: a thread is the clock."""
    import threading
    import time

    session = build_session(None, sim_overrides={**SMALL, "stepped": True, "faults": [{"kind": "reset", "at": [40]}]})
    cam, trig = session.sim.camera, session.sim.trigger
    loop = session.make_loop(timeout_s=3.0)
    stop = threading.Event()

    def clock() -> None:
        while not stop.is_set():
            time.sleep(0.012)
            try:
                trig.step()
            except Exception:  # not started yet, or stopped while closing
                pass

    ticker = threading.Thread(target=clock, daemon=True)
    sets = []
    try:
        loop.start()
        ticker.start()
        for _ in range(90):
            ev = loop.step()
            if ev.frameset is not None:
                ids = ev.frameset.frame_ids
                assert [cam.truth(i) for i in ids] == [0, 1], f"mispaired set {ids}"
                sets.append(tuple(f.trigger_count for f in ev.frameset.frames))
    finally:
        stop.set()
        ticker.join()
        loop.close()
    assert loop.stats.resyncs >= 1
    # pairs before the reset, then pairs again on the restarted counter (trigger counts start over)
    restarts = [i for i in range(1, len(sets)) if min(sets[i]) < min(sets[i - 1])]
    assert len(restarts) == 1 and restarts[0] >= 10 and len(sets) - restarts[0] >= 10, (sets, loop.stats)


def test_projector_window_closed_by_the_operator_stops_cleanly(tmp_path, sim_session):
    """A projector that reports stop_requested (pyglet: window closed, Esc or q in it) ends the
    session without an error; the recording is finalised."""
    from app.session import open_recorder
    from core.dump import read_dump

    session = build_session(None, sim_overrides=SMALL)
    rec = open_recorder(session, tmp_path / "rec")
    seen = []

    def close_window_after_20(frame) -> None:
        seen.append(frame)
        if len(seen) == 20:
            session.sim.projector.stop_requested = True  # what PygletProjector reports after a close

    pipe = LivePipeline(
        lambda: session.make_loop(timeout_s=3.0), sim_session[1], recorder=rec, on_frame=close_window_after_20
    )
    pipe.start()
    pipe.wait()
    rec.close()
    assert pipe.error is None and pipe.stop_reason == "the projector window was closed"
    assert pipe.capture.frames == 20
    assert len(read_dump(tmp_path / "rec").frames) == pipe.capture.confirmed >= pipe.capture.tagged - 2
