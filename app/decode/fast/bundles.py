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


class ChannelColumns(NamedTuple):
    """The lacking channel's row by column of one parity (lacking._channel_columns), int32. Per column holding it
    (index k: column 2k + cx): its sign (+1, else -1: NaN and 0 too), whether it has none (no_sign), the word of
    SPAN bits m of whether column k + m has no sign with at SPAN + m whether k + m's sign differs from k + m - 1's
    (words; spare: the other half of its doublings), and the bits m < 8 of whether column k + m's sign is +1
    (sign_bits). Per column lacking it (index l: column 2l + 1 - cx): its sign (lacking_sign, 0 for NaN and 0)
    and the bits m of whether it is > 0 at column l + m, at 8 + m whether < 0 (lacking_bits)."""

    sign: np.ndarray
    no_sign: np.ndarray
    words: np.ndarray
    sign_bits: np.ndarray
    lacking_sign: np.ndarray
    lacking_bits: np.ndarray
    spare: np.ndarray


class LackingScratch(NamedTuple):
    """One row of the lacking channel's signs (lacking.py), W pixels; the rows per pixel, event or run have room
    for the padding to whole vectors and for compressed stores. Per block of 8 the max |dG| at 1 + b with zero
    guards (g_max); per pixel G's threshold (g_threshold), its strong sign (sign, int8) and int32 flag (strong),
    whether an event is there (event, int8: a G edge at x, x + 1 or no strong sign at x). Per event
    (lacking._events): its pixel (event_pixel), whether it is an edge (is_edge), G's difference there and at the
    next pixel (g_at, g_next, float32), its position (event_position, float64). Per pair of consecutive events,
    a candidate run: its first column index (first_column), column count (column_span), the word of its first
    column (first_word), the sign changes and length per seen stripe (candidate_changes, candidate_ratio), int8
    flags of its pre-check, use and length (candidate, usable, long_candidate) and the candidates of more than
    SPAN columns (long_candidates). Per usable run: its first event (run_event), first column index
    (run_first_column), sign changes (run_changes), edges (run_e0, run_e1), length per seen stripe (run_ratio),
    local stripe width (local_width), stripe count (run_stripes, int64), stripes per pixel (run_scale), the sign
    bits of its first eight columns of either kind (held_bits, lacking_bits), its vote (votes), flip masks
    (flip_masks) and flags (long_run, emit), the runs emitted (emitted) and those of more than eight columns
    (long_runs), its phase where the flips read it (run_phase: a long run's own, or one carried across a G edge),
    its own phase (own_phase), whether _carried may give it one (refused, int8) and those runs (refused_runs). The
    channel's columns (ChannelColumns); the pixels whose sign flips (flips) and their camera difference of the
    channel once flipped, float32 (flipped_c, lacking_fill.py); the channel's camera differences, float32
    (camera_c, lacking_leak.py)."""

    g_max: np.ndarray
    g_threshold: np.ndarray
    sign: np.ndarray
    strong: np.ndarray
    event: np.ndarray
    event_pixel: np.ndarray
    is_edge: np.ndarray
    g_at: np.ndarray
    g_next: np.ndarray
    event_position: np.ndarray
    first_column: np.ndarray
    column_span: np.ndarray
    first_word: np.ndarray
    candidate_changes: np.ndarray
    candidate_ratio: np.ndarray
    candidate: np.ndarray
    usable: np.ndarray
    long_candidate: np.ndarray
    long_candidates: np.ndarray
    run_event: np.ndarray
    run_first_column: np.ndarray
    run_changes: np.ndarray
    run_e0: np.ndarray
    run_e1: np.ndarray
    run_ratio: np.ndarray
    local_width: np.ndarray
    run_stripes: np.ndarray
    run_scale: np.ndarray
    held_bits: np.ndarray
    lacking_bits: np.ndarray
    votes: np.ndarray
    flip_masks: np.ndarray
    long_run: np.ndarray
    emit: np.ndarray
    emitted: np.ndarray
    long_runs: np.ndarray
    own_phase: np.ndarray
    run_phase: np.ndarray
    refused: np.ndarray
    refused_runs: np.ndarray
    columns: ChannelColumns
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
