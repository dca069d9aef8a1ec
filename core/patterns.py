"""Stripe-pattern synthesis after Je, Lee & Park (2004), section 5, plus a Gray-code reference.

Pure: parameters in, arrays and plain data out; no I/O (see `core/pattern_export.py`).

One-shot: stripes of N colours (R, G, B for N = 3), adjacent stripes differ, every window of k
consecutive stripes is unique: n(N, k) = N (N-1)^(k-1) windows.
Two-shot: each stripe is an m-bit code, bit j = state of pattern channel j in frame 1 (1 = max);
adjacent codes differ in exactly one bit; frame 2 is the per-channel inverse of frame 1:
n2(m, k) = 2^m m^(k-1) windows.

Both sequences are generated as Eulerian circuits of the graph whose nodes are the valid
(k-1)-windows and whose edges are the valid k-windows. Such a circuit uses every valid window
exactly once, so the sequences reach the maximal lengths above, and it is cyclic: repeated across
a projector wider than one period, no window reappears before a whole period has passed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from core.errors import InputError

SCHEMES = ("one-shot", "two-shot", "graycode")

# Colour letters usable in a one-shot palette, as RGB triples of min/max flags.
PALETTE = {
    "R": (1, 0, 0),
    "G": (0, 1, 0),
    "B": (0, 0, 1),
    "C": (0, 1, 1),
    "M": (1, 0, 1),
    "Y": (1, 1, 0),
    "W": (1, 1, 1),
    "K": (0, 0, 0),
}
CHANNEL_INDEX = {"R": 0, "G": 1, "B": 2}

# Sequences longer than this are never useful on a projector and would be slow to build.
MAX_WINDOWS = 1 << 20


def n_one_shot(N: int, k: int) -> int:
    """Number of unique k-windows over N colours with adjacent colours different (eq. 1)."""
    return N * (N - 1) ** (k - 1)


def n_two_shot(m: int, k: int) -> int:
    """Number of unique k-windows of m-bit codes with one bit changing per step (eq. 7)."""
    return 2**m * m ** (k - 1)


def _eulerian_sequence(symbols: Sequence[int], allowed: Callable[[int, int], bool], k: int) -> list[int]:
    """Cyclic sequence in which every valid k-window (consecutive pairs allowed) appears once."""
    if k == 1:
        raise ValueError("k = 1 has no window graph; handled by the callers")
    succ_of = {a: [b for b in symbols if allowed(a, b)] for a in symbols}
    # Nodes: all valid (k-1)-words, built breadth-first so the order is deterministic.
    words: list[tuple[int, ...]] = [(s,) for s in symbols]
    for _ in range(k - 2):
        words = [(*w, b) for w in words for b in succ_of[w[-1]]]
    index = {w: i for i, w in enumerate(words)}
    out_edges = [[index[(*w[1:], b)] for b in succ_of[w[-1]]] for w in words]
    # Hierholzer's algorithm, iterative; pop from the end so edges are taken in reverse order.
    next_edge = [len(e) for e in out_edges]
    stack = [0]
    circuit: list[int] = []
    while stack:
        v = stack[-1]
        if next_edge[v]:
            next_edge[v] -= 1
            stack.append(out_edges[v][next_edge[v]])
        else:
            circuit.append(stack.pop())
    circuit.reverse()
    n_edges = sum(len(e) for e in out_edges)
    if len(circuit) != n_edges + 1:  # the window graph is always strongly connected here
        raise AssertionError("window graph is not Eulerian")
    return [words[v][0] for v in circuit[:-1]]


def _check_k(k: int) -> None:
    if not isinstance(k, int) or not 1 <= k <= 32:
        raise InputError(f"window length k={k!r} is out of range (1 to 32)")


@lru_cache(maxsize=64)
def one_shot_sequence(N: int = 3, k: int = 7) -> tuple[int, ...]:
    """Colour indices 0..N-1, cyclic, adjacent different, every cyclic k-window unique."""
    _check_k(k)
    if not isinstance(N, int) or not 2 <= N <= len(PALETTE):
        raise InputError(f"number of colours N={N!r} is out of range (2 to {len(PALETTE)})")
    check_window_keys(N, k, "one-shot pattern")  # (a sequence no decoder can hold the table of is of no use)
    if n_one_shot(N, k) > MAX_WINDOWS:
        raise InputError(f"n(N={N}, k={k}) = {n_one_shot(N, k)} windows is more than {MAX_WINDOWS}")
    if k == 1:
        return tuple(range(N))
    return tuple(_eulerian_sequence(range(N), lambda a, b: a != b, k))


def _gray(i: int) -> int:
    return i ^ (i >> 1)


@lru_cache(maxsize=64)
def two_shot_sequence(m: int = 2, k: int = 7) -> tuple[int, ...]:
    """m-bit codes, cyclic, exactly one bit changes between neighbours, every k-window unique."""
    _check_k(k)
    if not isinstance(m, int) or not 1 <= m <= 3:
        raise InputError(f"number of pattern channels m={m!r} is out of range (1 to 3)")
    check_window_keys(2**m, k, "two-shot pattern")
    if n_two_shot(m, k) > MAX_WINDOWS:
        raise InputError(f"n2(m={m}, k={k}) = {n_two_shot(m, k)} windows is more than {MAX_WINDOWS}")
    if k == 1:
        return tuple(_gray(i) for i in range(2**m))  # a cyclic Gray code visits every code once
    return tuple(_eulerian_sequence(range(2**m), lambda a, b: (a ^ b).bit_count() == 1, k))


MAX_WINDOW_KEYS = 1 << 24  # a decoder's window table: codes**k int32 entries, at most 64 MB


def check_window_keys(n_codes: int, k: int, where: str) -> None:
    """An InputError naming where unless a window table of n_codes**k keys fits MAX_WINDOW_KEYS."""
    if n_codes**k > MAX_WINDOW_KEYS:
        largest = max(j for j in range(1, 33) if n_codes**j <= MAX_WINDOW_KEYS)
        raise InputError(
            f"{where}: k={k} with {n_codes} codes needs a window table of {n_codes}^{k} entries; "
            f"at most k={largest} for {n_codes} codes"
        )


def window_table(sequence: Sequence[int], k: int) -> dict[tuple[int, ...], int]:
    """Map each cyclic k-window to the index of its first stripe in the sequence."""
    n = len(sequence)
    ext = list(sequence) + list(sequence[: k - 1])
    table = {tuple(ext[i : i + k]): i for i in range(n)}
    if len(table) != n:
        raise ValueError("sequence has repeated windows")
    return table


# ----------------------------------------------------------------------------- pattern sets


@dataclass(frozen=True)
class PatternSet:
    """The images of one scheme in projection order, and what a decoder needs to know."""

    scheme: str
    size: tuple[int, int]  # (W, H) projector pixels
    images: list[np.ndarray] = field(repr=False)  # RGB uint8 (H, W, 3)
    names: list[str]
    params: dict  # plain YAML-able data: k, stripe_width, sequence, channels, ...

    def __len__(self) -> int:
        return len(self.images)


def parse_size(text: str) -> tuple[int, int]:
    """'1024x768' -> (1024, 768)."""
    parts = str(text).lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise InputError(f"size {text!r} is not WxH (e.g. 1024x768)")
    w, h = (int(p) for p in parts)
    if w < 1 or h < 1 or w > 16384 or h > 16384:
        raise InputError(f"size {text!r} is out of range (1 to 16384 per side)")
    return w, h


def _check_size_for_window(size: tuple[int, int], k: int, stripe_width: int) -> None:
    if not isinstance(stripe_width, int) or stripe_width < 1:
        raise InputError(f"stripe width {stripe_width!r} must be a whole number of projector pixels >= 1")
    if size[0] < k * stripe_width:
        raise InputError(
            f"size {size[0]}x{size[1]} is too narrow for one window of k={k} stripes "
            f"{stripe_width} px wide (needs width >= {k * stripe_width})"
        )


def stripe_index_of_column(width: int, stripe_width: int) -> np.ndarray:
    """Stripe number (not wrapped) of every projector column."""
    return np.arange(width) // stripe_width


def _stripe_rows(row: np.ndarray, height: int) -> np.ndarray:
    return np.ascontiguousarray(np.broadcast_to(row[None, :, :], (height, *row.shape)))


def one_shot_patterns(
    size: tuple[int, int],
    k: int = 7,
    colors: str = "RGB",
    stripe_width: int = 1,
    min_value: int = 0,
    max_value: int = 255,
) -> PatternSet:
    """One image of saturated colour stripes; the sequence repeats to cover the width."""
    colors = colors.upper()
    if len(set(colors)) != len(colors) or not set(colors) <= set(PALETTE):
        raise InputError(f"colours {colors!r} must be distinct letters from {''.join(PALETTE)}")
    seq = one_shot_sequence(len(colors), k)
    _check_size_for_window(size, k, stripe_width)
    _check_levels(min_value, max_value)
    w, h = size
    lut = np.array([PALETTE[c] for c in colors], dtype=np.uint8)
    codes = np.asarray(seq)[stripe_index_of_column(w, stripe_width) % len(seq)]
    row = np.where(lut[codes] > 0, max_value, min_value).astype(np.uint8)
    params = {
        "k": k,
        "stripe_width": stripe_width,
        "colors": colors,
        "period": len(seq),
        "sequence": list(seq),
        "min_value": min_value,
        "max_value": max_value,
    }
    return PatternSet("one-shot", size, [_stripe_rows(row, h)], ["one_shot.png"], params)


def two_shot_patterns(
    size: tuple[int, int],
    k: int = 7,
    channels: str = "GB",
    stripe_width: int = 1,
    min_value: int = 0,
    max_value: int = 255,
) -> PatternSet:
    """Two images: frame 1 codes each stripe by channel min/max, frame 2 is its inverse."""
    channels = channels.upper()
    if not channels or len(set(channels)) != len(channels) or not set(channels) <= set(CHANNEL_INDEX):
        raise InputError(f"channels {channels!r} must be 1 to 3 distinct letters from RGB (e.g. GB)")
    seq = two_shot_sequence(len(channels), k)
    _check_size_for_window(size, k, stripe_width)
    _check_levels(min_value, max_value)
    w, h = size
    codes = np.asarray(seq)[stripe_index_of_column(w, stripe_width) % len(seq)]
    row1 = np.full((w, 3), min_value, np.uint8)
    row2 = np.full((w, 3), min_value, np.uint8)
    for bit, ch in enumerate(channels):
        on = (codes >> bit) & 1 == 1
        row1[:, CHANNEL_INDEX[ch]] = np.where(on, max_value, min_value)
        row2[:, CHANNEL_INDEX[ch]] = np.where(on, min_value, max_value)
    params = {
        "k": k,
        "stripe_width": stripe_width,
        "channels": channels,
        "period": len(seq),
        "sequence": list(seq),
        "min_value": min_value,
        "max_value": max_value,
        "code_bits": "bit j of a code is channels[j] in frame 1 (1 = max_value); frame 2 is inverted",
    }
    return PatternSet(
        "two-shot", size, [_stripe_rows(row1, h), _stripe_rows(row2, h)], ["frame1.png", "frame2.png"], params
    )


def gray_code_bits(n: int) -> int:
    """Bits needed to label n positions."""
    return max(1, (n - 1).bit_length())


def graycode_patterns(size: tuple[int, int], min_value: int = 0, max_value: int = 255) -> PatternSet:
    """White, black, then for columns and then rows each Gray-code bit (MSB first) and its inverse.

    `params["frames"]` gives each image's role: {kind: white|black|column|row, bit, inverse}.
    Bit b of position p is bit b of gray(p) = p ^ (p >> 1); the white/black pair gives a per-pixel
    threshold and the inverse of each bit pattern a robust per-pixel comparison.
    """
    _check_levels(min_value, max_value)
    w, h = size
    images: list[np.ndarray] = []
    names: list[str] = []
    roles: list[dict] = []

    def add(img: np.ndarray, name: str, role: dict) -> None:
        images.append(img)
        names.append(f"{len(images) - 1:02d}_{name}.png")
        roles.append(role)

    add(np.full((h, w, 3), max_value, np.uint8), "white", {"kind": "white"})
    add(np.full((h, w, 3), min_value, np.uint8), "black", {"kind": "black"})
    for kind, n in (("column", w), ("row", h)):
        gray = np.arange(n) ^ (np.arange(n) >> 1)
        for bit in reversed(range(gray_code_bits(n))):
            on = (gray >> bit) & 1 == 1
            for inverse in (False, True):
                line = np.where(on != inverse, max_value, min_value).astype(np.uint8)
                if kind == "column":
                    img = np.broadcast_to(line[None, :, None], (h, w, 3))
                else:
                    img = np.broadcast_to(line[:, None, None], (h, w, 3))
                suffix = "_inv" if inverse else ""
                add(np.ascontiguousarray(img), f"{kind}_b{bit}{suffix}", {"kind": kind, "bit": bit, "inverse": inverse})
    params = {
        "column_bits": gray_code_bits(w),
        "row_bits": gray_code_bits(h),
        "min_value": min_value,
        "max_value": max_value,
        "frames": roles,
    }
    return PatternSet("graycode", size, images, names, params)


def _check_levels(min_value: int, max_value: int) -> None:
    if not (0 <= min_value < max_value <= 255):
        raise InputError(f"levels min={min_value} max={max_value} must satisfy 0 <= min < max <= 255")


def make_patterns(scheme: str, size: tuple[int, int], **options) -> PatternSet:
    """Build the pattern set of a scheme; options are those of the scheme's function."""
    builders = {"one-shot": one_shot_patterns, "two-shot": two_shot_patterns, "graycode": graycode_patterns}
    if scheme not in builders:
        raise InputError(f"unknown scheme {scheme!r} (choose one of {', '.join(SCHEMES)})")
    return builders[scheme](size, **options)
