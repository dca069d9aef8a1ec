"""Grouping tagged frames into frame sets: complete, correctly tagged, never across a gap."""

from __future__ import annotations

from app.framesets import group_frame_sets


def test_two_shot_pairs_slide_and_know_their_order():
    tags = [(10, 0), (11, 1), (12, 0), (13, 1)]
    sets, stats = group_frame_sets(tags, "two-shot", 2)
    assert [s.indices for s in sets] == [(0, 1), (2, 1), (2, 3)]
    assert [s.reversed_order for s in sets] == [False, True, False]
    assert stats.gaps == 0 and stats.sets == 3


def test_two_shot_disjoint_pairs():
    sets, _ = group_frame_sets([(0, 0), (1, 1), (2, 0), (3, 1)], "two-shot", 2, sliding=False)
    assert [s.indices for s in sets] == [(0, 1), (2, 3)]


def test_gap_and_wrong_tag_never_pair():
    tags = [(0, 0), (2, 1), (3, 1), (4, 0), (5, 7)]
    sets, stats = group_frame_sets(tags, "two-shot", 2)
    assert [s.indices for s in sets] == [(3, 2)]  # only 3-4 (frames 2, 3): consecutive ids, tags {1, 0}
    assert stats.gaps == 1 and stats.bad_tags == 2


def test_reversed_first_pair():
    sets, _ = group_frame_sets([(5, 1), (6, 0)], "two-shot", 2)
    assert sets[0].indices == (1, 0) and sets[0].reversed_order


def test_one_shot_and_graycode():
    sets, _ = group_frame_sets([(0, 0), (1, 0)], "one-shot", 1)
    assert [s.indices for s in sets] == [(0,), (1,)]
    tags = [(0, 0), (1, 1), (2, 2), (3, 0), (5, 1), (6, 2), (7, 0), (8, 1), (9, 2)]
    sets, stats = group_frame_sets(tags, "graycode", 3)
    assert [s.indices for s in sets] == [(0, 1, 2), (6, 7, 8)]
    assert stats.gaps == 1
