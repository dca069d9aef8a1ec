"""Stripe-pattern synthesis: the paper's counts, rules (a)-(d), maximal cyclic sequences, exact images."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.errors import InputError
from core.patterns import (
    PALETTE,
    gray_code_bits,
    graycode_patterns,
    make_patterns,
    n_one_shot,
    n_two_shot,
    one_shot_patterns,
    one_shot_sequence,
    parse_size,
    two_shot_patterns,
    two_shot_sequence,
    window_table,
)


def cyclic_windows(seq, k):
    n = len(seq)
    return [tuple(seq[(i + j) % n] for j in range(k)) for i in range(n)]


# --------------------------------------------------------------------------- the paper's numbers


def test_counts_match_the_paper():
    assert [n_one_shot(3, k) for k in (1, 2, 3, 4, 5)] == [3, 6, 12, 24, 48]
    assert n_one_shot(3, 7) == 192
    assert n_two_shot(2, 7) == 256
    assert n_one_shot(2, 9) == 2  # binary BW stripes gain nothing from longer windows (section 2)
    assert n_two_shot(3, 7) == 8 * 3**6


def test_paper_sequences_reach_their_maximal_lengths():
    assert len(one_shot_sequence(3, 7)) == 192
    assert len(two_shot_sequence(2, 7)) == 256


# --------------------------------------------------------------------------- rules (a)-(d)


@settings(max_examples=60, deadline=None)
@given(N=st.integers(2, 5), k=st.integers(1, 6))
def test_one_shot_rules_and_maximal_length(N, k):
    seq = one_shot_sequence(N, k)
    # Maximal: every valid window appears exactly once (cyclic de Bruijn-like sequence).
    assert len(seq) == n_one_shot(N, k)
    assert set(seq) <= set(range(N))
    # (a) adjacent stripes differ, also across the seam where the sequence repeats.
    assert all(seq[i] != seq[(i + 1) % len(seq)] for i in range(len(seq)))
    # (b) every cyclic window of k stripes is unique.
    windows = cyclic_windows(seq, k)
    assert len(set(windows)) == len(windows)


@settings(max_examples=60, deadline=None)
@given(m=st.integers(1, 3), k=st.integers(1, 6))
def test_two_shot_rules_and_maximal_length(m, k):
    seq = two_shot_sequence(m, k)
    assert len(seq) == n_two_shot(m, k)
    assert set(seq) <= set(range(2**m))
    # (a) + (c): neighbours differ in exactly one channel, across the seam too.
    assert all((seq[i] ^ seq[(i + 1) % len(seq)]).bit_count() == 1 for i in range(len(seq)))
    # (b) unique cyclic windows.
    windows = cyclic_windows(seq, k)
    assert len(set(windows)) == len(windows)


@settings(max_examples=40, deadline=None)
@given(
    channels=st.sampled_from(["GB", "RG", "RB", "RGB", "G", "BG"]),
    k=st.integers(2, 5),
    width=st.integers(1, 3),
    cols=st.integers(40, 300),
)
def test_two_shot_images_rule_d_inverse_and_exact_levels(channels, k, width, cols):
    cols = max(cols, k * width)
    p = two_shot_patterns((cols, 3), k=k, channels=channels, stripe_width=width)
    f1, f2 = p.images
    assert f1.dtype == np.uint8 and f1.shape == (3, cols, 3)
    assert set(np.unique(f1)) <= {0, 255} and set(np.unique(f2)) <= {0, 255}
    on = [ch in channels for ch in "RGB"]
    for c in range(3):
        if on[c]:
            # (d) frame 2 is the per-channel inverse of frame 1
            assert np.array_equal(f2[..., c], 255 - f1[..., c])
        else:
            assert not f1[..., c].any() and not f2[..., c].any()
    # (c) along a row, neighbouring stripes differ in exactly one channel; inside a stripe nothing changes.
    row = f1[0].astype(int)
    changes = (row[1:] != row[:-1]).sum(axis=1)
    boundary = (np.arange(1, cols) % width) == 0
    assert np.all(changes[boundary] == 1)
    assert np.all(changes[~boundary] == 0)
    # every row identical (vertical stripes)
    assert np.array_equal(f1[0], f1[-1])


# --------------------------------------------------------------------------- images, exact pixels


def test_two_shot_default_on_1024_columns_repeats_256_stripes_four_times():
    p = two_shot_patterns((1024, 768))
    f1, f2 = p.images
    seq = two_shot_sequence(2, 7)
    g, b = f1[0, :, 1] > 0, f1[0, :, 2] > 0
    codes = g.astype(int) | (b.astype(int) << 1)  # bit 0 = G, bit 1 = B ("GB")
    assert np.array_equal(codes, np.tile(seq, 4))
    assert np.array_equal(f2[..., 1:], 255 - f1[..., 1:])
    assert not f1[..., 0].any()
    assert p.params["period"] == 256 and p.params["channels"] == "GB" and p.params["k"] == 7


def test_one_shot_image_uses_only_saturated_rgb_with_stripe_width():
    p = one_shot_patterns((500, 4), stripe_width=2)
    (img,) = p.images
    seq = one_shot_sequence(3, 7)
    assert set(map(tuple, img.reshape(-1, 3))) <= {(255, 0, 0), (0, 255, 0), (0, 0, 255)}
    expect = np.array([PALETTE["RGB"[seq[(x // 2) % 192]]] for x in range(500)]) * 255
    assert np.array_equal(img[0], expect)
    assert np.array_equal(img[3], expect)


def test_repeated_sequence_windows_do_not_recur_within_a_period():
    # Across the seam of the repetition, a window reappears only one whole period later.
    p = two_shot_patterns((1024, 2))
    seq = p.params["sequence"]
    codes = np.tile(seq, 4)
    last_seen = {}
    for x in range(len(codes) - 6):
        w = tuple(codes[x : x + 7])
        if w in last_seen:
            assert x - last_seen[w] == 256
        last_seen[w] = x
    assert len(last_seen) == 256


def test_window_table_maps_every_window_to_its_start():
    seq = two_shot_sequence(2, 7)
    table = window_table(seq, 7)
    assert len(table) == 256
    for w, i in list(table.items())[:50]:
        assert tuple(seq[(i + j) % 256] for j in range(7)) == w


def test_graycode_columns_rows_inverses_white_black():
    W, H = 100, 37
    p = graycode_patterns((W, H))
    roles = p.params["frames"]
    assert len(p) == 2 + 2 * gray_code_bits(W) + 2 * gray_code_bits(H) == len(roles)
    assert (p.images[0] == 255).all() and (p.images[1] == 0).all()
    # decode the column code from the non-inverted images and check it is gray(x), neighbours differ by 1 bit
    col_code = np.zeros(W, int)
    row_code = np.zeros(H, int)
    for img, role in zip(p.images, roles, strict=True):
        if role["kind"] in ("column", "row"):
            assert set(np.unique(img)) <= {0, 255}
        if role["kind"] == "column" and not role["inverse"]:
            col_code |= (img[0, :, 0] > 0).astype(int) << role["bit"]
            assert (img == img[:1]).all()  # vertical
        if role["kind"] == "row" and not role["inverse"]:
            row_code |= (img[:, 0, 0] > 0).astype(int) << role["bit"]
    x = np.arange(W)
    assert np.array_equal(col_code, x ^ (x >> 1))
    y = np.arange(H)
    assert np.array_equal(row_code, y ^ (y >> 1))
    for i in range(2, len(p), 2):  # each bit image is followed by its inverse
        assert roles[i + 1]["inverse"] and np.array_equal(p.images[i + 1], 255 - p.images[i])


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "call",
    [
        lambda: make_patterns("three-shot", (100, 10)),
        lambda: one_shot_patterns((6, 10), k=7),
        lambda: two_shot_patterns((13, 10), k=7, stripe_width=2),
        lambda: one_shot_sequence(1, 7),
        lambda: one_shot_sequence(9, 3),
        lambda: two_shot_sequence(4, 3),
        lambda: two_shot_sequence(2, 0),
        lambda: two_shot_patterns((100, 10), channels="GX"),
        lambda: one_shot_patterns((100, 10), colors="RRG"),
        lambda: two_shot_patterns((100, 10), stripe_width=0),
        lambda: parse_size("1024*768"),
        lambda: parse_size("0x768"),
    ],
)
def test_bad_parameters_raise_input_error(call):
    with pytest.raises(InputError):
        call()
