"""Texture frames in the frame checker as pure logic: never in a set, costing two sliding pairs, and a late flip on
either side of one (a texture frame that still shows a pattern, a pattern frame that still shows white) refused."""

from __future__ import annotations

import numpy as np
import pytest

from app.capture import FlipLog, FrameChecker, Shown
from drivers.base import Frame

from .test_pairing import assert_all_sets_correct, true_of, truth_frame

TEXTURE = 2


def white_frame(tick: int, frame_id: int, rng) -> Frame:
    img = (np.full((32, 32, 3), 220, np.int16) + rng.integers(-4, 5, (32, 32, 3))).clip(0, 255).astype(np.uint8)
    img[0, 0, 0] = TEXTURE
    img[0, 1] = np.frombuffer(np.uint32(tick).tobytes()[:3], np.uint8)
    return Frame(img, frame_id, 1000 * tick)


def run(texture_ticks: set[int], seen_late: set[int] = frozenset(), ticks: int = 40):
    """Ticks 0..ticks-1, pattern tick % 2 or the texture at texture_ticks; at seen_late the camera sees what the
    tick before showed (a flip no counter noticed)."""
    rng = np.random.default_rng(0)
    log = FlipLog()
    checker = FrameChecker("two-shot", 2, log, check_alternation=True, texture_pattern=TEXTURE)
    checker.anchor_frame_id(100, 0)
    shown = {t: TEXTURE if t in texture_ticks else t % 2 for t in range(ticks)}
    sets, tagged, confirmed = [], [], []
    for t in range(ticks):
        log.record(Shown(t, shown[t], t))
        seen = shown[t - 1] if t in seen_late else shown[t]
        f = white_frame(t, 100 + t, rng) if seen == TEXTURE else truth_frame(t, seen, 100 + t, rng)
        frame, fs = checker.push(f)
        confirmed.extend(checker.confirmed)
        if frame is not None:
            tagged.append(frame)
        if fs is not None:
            sets.append(fs)
    return sets, checker.stats, tagged, confirmed


def test_texture_frames_are_in_no_set_and_cost_two_pairs_each():
    clean, _, _, _ = run(set())
    sets, stats, tagged, confirmed = run({10, 21, 30})
    assert_all_sets_correct(sets, 2)
    assert all(true_of(f)[0] != TEXTURE for fs in sets for f in fs.frames)
    assert all(fs.previous is None or true_of(fs.previous)[0] != TEXTURE for fs in sets)
    assert stats.textures == 3 and stats.refused == 0
    assert len(sets) == len(clean) - 2 * 3  # the two pairs that would hold each texture frame
    # a texture frame is tagged as one, and recorded (confirmed) like every checked frame
    assert [f.frame_id for f in tagged if f.pattern == TEXTURE] == [110, 121, 130]
    assert {f.frame_id for f in confirmed} >= {110, 121, 130}
    # the pairs right after a texture frame are there, and their previous frame is not the texture
    after = [fs for fs in sets if min(fs.frame_ids) == 111]
    assert len(after) == 1 and after[0].previous is None


@pytest.mark.parametrize("late", [10, 11, 12])
def test_a_late_flip_next_to_a_texture_frame_is_refused(late):
    """10: the texture frame still shows pattern 1; 11: the pattern frame after it still shows white; 12: the frame
    after that still shows the pattern of 11."""
    sets, stats, tagged, _ = run({10}, {late})
    assert stats.mistagged == 1, stats
    assert_all_sets_correct(sets, 2)
    assert all(true_of(f)[0] == f.pattern for f in tagged)  # every tag handed on is what the frame saw
