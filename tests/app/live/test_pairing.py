"""Tagging and pairing as pure logic: no fault (drop, duplicate, swap, late flip, trigger reset)
ever lets a mispaired frame set through, and the counters say what happened.

Each synthetic frame carries its ground truth in its pixels (the pattern it really saw and its
true exposure tick), so every emitted set is checked against the truth, not against the tags.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.capture import FlipLog, FrameChecker, Shown
from app.framesets import group_frame_sets
from drivers.base import Frame

FAULTS = ("ok", "drop", "dup", "dup_new_id", "swap", "late", "late_unnoticed", "late_silent", "reset")
STRIPES = (np.arange(32)[None, :, None] // 2 % 2 == 0) & np.ones((32, 1, 3), bool)


def truth_frame(tick: int, seen: int, frame_id: int, rng, **kw) -> Frame:
    """A 32x32 'camera image' of pattern `seen` (stripes, the inverse, ...) with sensor noise."""
    on = STRIPES if seen % 2 == 0 else ~STRIPES
    on = np.roll(on, seen // 2, axis=1) if seen > 1 else on  # Gray-code-like: every pattern differs
    img = np.where(on, 180, 40).astype(np.int16) + rng.integers(-4, 5, (32, 32, 3))
    img = img.clip(0, 255).astype(np.uint8)
    img[0, 0, 0] = seen
    img[0, 1] = np.frombuffer(np.uint32(tick).tobytes()[:3], np.uint8)
    return Frame(img, frame_id, 1000 * tick, **kw)


def true_of(frame: Frame) -> tuple[int, int]:
    tick = int.from_bytes(bytes(frame.image[0, 1]) + b"\0", "little")
    return int(frame.image[0, 0, 0]), tick


def simulate(faults: list[str], scheme: str = "two-shot", n: int = 2, use_trigger: bool = False, seed: int = 0):
    """Run a fault script through a FrameChecker; return (emitted sets, stats, delivered frames)."""
    rng = np.random.default_rng(seed)
    log = FlipLog()
    checker = FrameChecker(scheme, n, log, check_alternation=scheme != "one-shot")
    delivered: list[Frame] = []
    confirmed: list[Frame] = []  # what a recorder would write
    sets = []
    tick = 0
    trig_base = 0  # tick of trigger count 1
    pending_swap: Frame | None = None

    def deliver(f: Frame) -> None:
        delivered.append(f)
        _, fs = checker.push(f)
        confirmed.extend(checker.confirmed)
        if fs is not None:
            sets.append(fs)

    if not use_trigger:
        checker.anchor_frame_id(100, 0)
    previous = "ok"
    counted_since_reset = False
    for fault in faults:
        if fault == previous == "late_silent":
            # Late on every refresh is a projector running one frame behind: the pixels alternate
            # perfectly, and only a phase marker (late_unnoticed) or the flip times (late) can tell.
            fault = "ok"
        previous = fault
        shown = tick % n
        seen = shown
        late = False
        if fault == "late":  # flip missed its refresh, and the loop saw it in the flip time
            seen, late = (tick - 1) % n, True
        elif fault in ("late_unnoticed", "late_silent"):  # a marker line knows, or nothing but the pixels
            seen = (tick - 1) % n
        log.record(Shown(tick, shown, tick, late))
        kw = {}
        if use_trigger:
            kw["trigger_count"] = tick - trig_base + 1
        if fault == "late_unnoticed":
            kw["pattern"] = seen  # e.g. a MARK line read by the camera
        f = truth_frame(tick, seen, 100 + tick, rng, **kw)
        if fault == "reset" and use_trigger and not counted_since_reset:
            fault = "ok"  # a reset shows as a count going back: it needs a count seen before it (real
            # boxes stop when they reset, so the loop restarts them before any frame of a new count)
        if fault == "reset" and use_trigger:
            # the box rebooted: this frame's count restarts at 1; the loop re-anchors a few ticks later
            f = dataclasses.replace(f, trigger_count=1)
            deliver(f)
            trig_base = tick  # the loop restarted the schedule: count k is now tick trig_base + k - 1
            checker.anchor_trigger(trig_base)
            counted_since_reset = True  # the checker saw count 1: a second reset goes back to it
            tick += 1
            continue
        if fault != "drop":
            counted_since_reset = True
        if fault == "drop":
            pass
        elif fault == "swap":
            pending_swap = f  # delivered after the next frame
        else:
            deliver(f)
            if pending_swap is not None:
                deliver(pending_swap)
                pending_swap = None
            if fault == "dup":
                deliver(f)
            elif fault == "dup_new_id":  # the same buffer again under the next id
                tick += 1
                log.record(Shown(tick, tick % n, tick))
                deliver(dataclasses.replace(f, frame_id=f.frame_id + 1))
        tick += 1
    simulate.confirmed = confirmed
    return sets, checker.stats, delivered


def assert_all_sets_correct(sets, n: int) -> None:
    for fs in sets:
        truths = [true_of(f) for f in fs.frames]
        assert [s for s, _ in truths] == list(range(n)), f"mispaired set: {truths}"
        ticks = sorted(t for _, t in truths)
        assert ticks == list(range(ticks[0], ticks[0] + n)), f"frames not consecutive: {ticks}"


def test_clean_stream_gives_a_pair_per_frame_sliding():
    sets, stats, _ = simulate(["ok"] * 20)
    # every frame from the fourth on pairs with its predecessor (the pixel check needs, for each
    # frame of a pair, the frame of the same pattern one cycle before)
    assert len(sets) == 17 and stats.refused == 0 and stats.dropped == 0
    assert_all_sets_correct(sets, 2)
    # orders alternate: frame 1 of a pair is pattern 0 or pattern 1 in turn
    assert [fs.reversed_order for fs in sets[:4]] == [False, True, False, True]


def test_each_fault_is_detected_and_counted():
    cases = {
        "drop": ("dropped", 1),
        "dup": ("duplicates", 1),
        "dup_new_id": ("duplicates", 1),
        "swap": ("out_of_order", 1),
        "late": ("mistagged", 1),
        "late_unnoticed": ("mistagged", 1),
        "late_silent": ("mistagged", 1),  # caught by the pixels: it repeats the previous pattern
    }
    for fault, (counter, count) in cases.items():
        sets, stats, _ = simulate(["ok"] * 6 + [fault] + ["ok"] * 6)
        assert getattr(stats, counter) == count, (fault, stats)
        assert_all_sets_correct(sets, 2)
        assert len(sets) >= 6, (fault, len(sets))  # pairing resumes right after


def test_trigger_reset_is_refused_then_pairing_resumes():
    sets, stats, _ = simulate(["ok"] * 6 + ["reset"] + ["ok"] * 8, use_trigger=True)
    assert stats.untracked == 1
    assert_all_sets_correct(sets, 2)
    assert len(sets) == 3 + 5  # before the reset, and after it once each frame has its checks


def test_assuming_tags_would_mispair_the_same_streams():
    """The fault scripts are strong enough: tags assumed from the arrival order decode wrong sets."""
    _, _, delivered = simulate(["ok"] * 5 + ["late_silent", "swap", "ok", "dup", "ok"] + ["ok"] * 5)
    tags = [(i, i % 2) for i in range(len(delivered))]  # 0, 1, 0, 1 by arrival: the tag assumed
    naive, _ = group_frame_sets(tags, "two-shot", 2)
    wrong = 0
    for fs in naive:
        frames = [delivered[i] for i in fs.indices]
        if [true_of(f)[0] for f in frames] != [0, 1]:
            wrong += 1
    assert wrong >= 4


@settings(max_examples=150, deadline=None)
@given(st.lists(st.sampled_from(FAULTS), min_size=5, max_size=80), st.booleans(), st.integers(0, 3))
def test_no_fault_sequence_ever_yields_a_mispaired_set(faults, use_trigger, seed):
    sets, stats, delivered = simulate(faults, use_trigger=use_trigger, seed=seed)
    assert_all_sets_correct(sets, 2)
    assert stats.frames == len(delivered)
    assert stats.tagged + stats.refused == stats.frames
    # what the recorder gets: each frame once, in order, with the pattern it really saw
    recorded = simulate.confirmed
    assert all(f.pattern == true_of(f)[0] for f in recorded)
    assert [f.frame_id for f in recorded] == sorted({f.frame_id for f in recorded})
    assert len(recorded) == stats.confirmed <= stats.tagged


@settings(max_examples=60, deadline=None)
@given(st.lists(st.sampled_from(FAULTS), min_size=12, max_size=80), st.integers(0, 3))
def test_graycode_sets_are_complete_and_in_order(faults, seed):
    n = 6
    sets, _, _ = simulate(faults, scheme="graycode", n=n, seed=seed)
    assert_all_sets_correct(sets, n)


def test_one_shot_every_checked_frame_is_a_set():
    sets, stats, _ = simulate(["ok", "dup", "ok", "drop", "ok"], scheme="one-shot", n=1)
    assert len(sets) == stats.tagged == 4 and stats.duplicates == 1
