"""The named bundles the fast decoder's stages take: numba-compatible named tuples of arrays and scalars.

A bundle is one argument of a compiled function; once the callee is inlined its fields are plain values, so a
bundle costs nothing at run time. Each buffer has one name and one purpose; where one buffer is read under two
dtypes (a float32 pair gathered as one int64), both names are fields of one bundle and documented there.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from app.decode.response_inverse import ResponseInverse


class FrameTables(NamedTuple):
    """The camera response, read per pixel: linearised value and noise slope (3, levels) float32, and `packed`,
    the two read together (pair_tables for 8-bit frames, else pack_tables; int64 entries of float32 pairs); and
    its inverse, a linear value back to a code (app/decode/response_inverse.py: the lacking channel's moved fill,
    lacking_fill.py)."""

    lin: np.ndarray
    dlin: np.ndarray
    packed: np.ndarray
    inverse: ResponseInverse


NO_LACKING = (-1, -1, -1)  # Classifier.lacking of frames not reconstructed from a raw mosaic
NO_LEAK = (-1, -1, -1, 0)  # Classifier.leak of frames not reconstructed from a raw mosaic


class Classifier(NamedTuple):
    """Two-shot classification: the unmixing rows (m, 3) float32 of the pattern channels, the noise floor t_abs
    (raw 8-bit steps), the shares t_rel (a code) and t_rel_edge (a zero-crossing sign) of the local amplitude
    (float32), and the pixels per block of that amplitude. lacking: for frames reconstructed from a raw mosaic,
    (pattern channel of G, camera channel of the other pattern channel, column parity holding it), whose signs
    the G edges give where its columns alias the stripes (lacking.py); NO_LACKING for other frames. leak: for
    such frames, mirrored or not, (pattern channel of G, camera channel of the other, column parity holding it
    as the camera saw it, 1 if the rows are mirrored), whose leak into G is removed at its stripes' amplitude
    (lacking_leak.py); NO_LEAK for other frames."""

    unmix: np.ndarray
    t_abs: np.float32
    t_rel: np.float32
    t_rel_edge: np.float32
    block: int
    lacking: tuple[int, int, int]
    leak: tuple[int, int, int, int]


class StripeCode(NamedTuple):
    """A stripe sequence's tables (WindowSpec): window key -> sequence position (A**k,) int32, which codes may
    be neighbours (A, A) bool, and the edge signal's channel weights (A, A, C) float32."""

    table: np.ndarray
    link_ok: np.ndarray
    weights: np.ndarray


class LabelSettings(NamedTuple):
    """Labelling: window length k, sequence period, stripe width (projector px), copies of the sequence across
    the projector and its width, the pixel gap allowed between linked runs, the copy vote's share, the node
    smoothing half-width, the vertical check's tolerance and support (tol <= 0: no check), nodes at edges (else
    centres), whether the per-pixel column range is read, and for frames reconstructed from a raw mosaic the
    code bit of the channel it samples in every other column (its edges placed from the G edges:
    lacking_edges.py; 0: none)."""

    k: int
    period: int
    stripe_width: int
    n_copies: int
    proj_width: int
    gap_max: int
    min_frac: float
    smooth: int
    tol: float
    min_support: float
    edges_mode: bool
    use_range: bool
    lacking_bit: int


class Geometry(NamedTuple):
    """Per pixel: the projector columns the depth range allows [lo, hi] (H, W) float32 ((1, 1) when unused), the
    Moebius planes (3, H, W) float32 with w0 and w_span (float32), and the depth map (H, W) float32 they fill
    ((0, 0): none)."""

    lo: np.ndarray
    hi: np.ndarray
    planes: np.ndarray
    w0: np.float32
    w_span: np.float32
    depth: np.ndarray


class Runs(NamedTuple):
    """A row's runs: run j covers pixels start[j] .. end[j] with code code[j], link[j] says whether it is linked
    to run j + 1, edge[j] is the sub-pixel edge between them; slow lists the links the edge search revisits."""

    start: np.ndarray
    end: np.ndarray
    code: np.ndarray
    link: np.ndarray
    edge: np.ndarray
    slow: np.ndarray


class EventScratch(NamedTuple):
    """The zero-crossing segmentation's per-channel events (position, sign, kind: (C, n)), their counts (C,),
    the merge's pointers and signs (2, C) and the stripes' sub-pixel left and right bounds (n,)."""

    x: np.ndarray
    sign: np.ndarray
    kind: np.ndarray
    count: np.ndarray
    merge: np.ndarray
    left: np.ndarray
    right: np.ndarray


class LackingScratch(NamedTuple):
    """One row of the lacking channel's signs (lacking.py), W pixels: per block of 8 the max |dG| at 1 + b with
    zero guards (g_max), the strong G signs (sign, int8); int8 flags per pixel, event or run (event, flag_a,
    flag_b); rows per pixel, event or run of int32 (i32), float64 (f64), float32 (gx: G's thresholds per
    pixel, then its differences at the events' pixels, and gx1 at the pixels after them) and int64 (n: a run's
    stripe count); rows per column of one parity, int32 (cols); the pixels whose sign flips (flips) and their
    camera difference of the channel once flipped, float32 (flipped_c, lacking_fill.py); the channel's camera
    differences, float32 (camera_c, lacking_leak.py). lacking.py names each row where it uses it; the rows per
    pixel, event or run have room for the padding to whole vectors and for compressed stores."""

    g_max: np.ndarray
    sign: np.ndarray
    event: np.ndarray
    flag_a: np.ndarray
    flag_b: np.ndarray
    i32: tuple
    f64: tuple
    gx: np.ndarray
    gx1: np.ndarray
    cols: tuple
    n: np.ndarray
    flips: np.ndarray
    camera_c: np.ndarray
    flipped_c: np.ndarray


class ClassifyScratch(NamedTuple):
    """One row of classification. rows (2m, W) float32: rows 0..m-1 the unmixed differences, rows m..2m-1 the
    noise floors, raised in place to the zero-crossing sign thresholds. block_max (max(m, 2), nb + 2): each
    block's max |d|, at 1 + b with zero guards; block_thr (2, nb + 2) and pixel_thr (2, W): the two-channel
    path's code thresholds per block and spread over the pixels; code (W,) int8 the row's codes; lacking: the
    lacking channel's signs (Classifier.lacking)."""

    rows: np.ndarray
    block_max: np.ndarray
    block_thr: np.ndarray
    pixel_thr: np.ndarray
    code: np.ndarray
    lacking: LackingScratch


class LabelScratch(NamedTuple):
    """One row of labelling, for up to n runs.

    keys, pos: the windows' keys and sequence positions; confirmed: each window's offset (position less its index, mod
    the period) if confirmed (six -1 first); label: the runs' labels; linked_next, starts, ends (int8) and first_run,
    last_run: the chains' ends; nodes_x, nodes_v, smoothed: a chain's nodes (pixel, projector column); node_px,
    first_copy, node_lo, node_hi: the copy vote per node; votes: per copy. seg_lines (int64) holds each segment's line
    as a float32 pair (column at the chain's first pixel, slope), written through its float32 view seg_halves; px_lines
    and px_halves likewise per pixel; seg_first and seg_of map pixels to segments."""

    keys: np.ndarray
    pos: np.ndarray
    confirmed: np.ndarray
    label: np.ndarray
    linked_next: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    first_run: np.ndarray
    last_run: np.ndarray
    nodes_x: np.ndarray
    nodes_v: np.ndarray
    smoothed: np.ndarray
    node_px: np.ndarray
    first_copy: np.ndarray
    node_lo: np.ndarray
    node_hi: np.ndarray
    votes: np.ndarray
    seg_lines: np.ndarray
    seg_halves: np.ndarray
    px_lines: np.ndarray
    px_halves: np.ndarray
    seg_first: np.ndarray
    seg_of: np.ndarray


class ChainMap(NamedTuple):
    """A labelled map and its chains: columns (H, W) float32 (NaN: none), chain ids (R, W) int32 (-1: none; row y
    at y % R, so R >= 2 rows may be kept), and per chain c: vertical agreements, disagreements, pixels, first and
    last pixel span[c] and, per row y, the first chain first[y]. Counting needs room for chain c in npx."""

    col: np.ndarray
    chain: np.ndarray
    agree: np.ndarray
    disagree: np.ndarray
    npx: np.ndarray
    span: np.ndarray
    first: np.ndarray


class RowScratch(NamedTuple):
    """Everything a row of the fused decoder writes before its columns: classification, runs, events, labels."""

    classify: ClassifyScratch
    runs: Runs
    events: EventScratch
    label: LabelScratch


class LinkScratch(NamedTuple):
    """The gathered link pass's rows, for up to n runs: per link j the transition rc[j] * A + rc[j + 1] (pair),
    its packed link bits and difference-row offset (info), the flat positions of the two facing pixels' edge
    signal (at0, at1), the transition's weight and the two gathered differences (value0, value1), and the
    flag of the links to search; info_rows (A * A,): the transition table's info with row offsets."""

    pair: np.ndarray
    info: np.ndarray
    at0: np.ndarray
    at1: np.ndarray
    weight: np.ndarray
    value0: np.ndarray
    value1: np.ndarray
    info_rows: np.ndarray
    flag: np.ndarray


class Transitions(NamedTuple):
    """Per code transition t = a * A + b: whether it can link two runs, the first channel of its edge signal,
    that channel's weight, whether more channels weigh in (one-shot), the three packed into one int64
    (ok | more << 1 | channel << 2), whether the table is the two-shot bit rule (runs._bit_link), and the link
    pass's rows."""

    ok: np.ndarray
    channel: np.ndarray
    weight: np.ndarray
    more: np.ndarray
    info: np.ndarray
    bits: bool
    link: LinkScratch
