"""The row loop: label rows one at a time (label_rows), or decode two-shot pairs fused row by row (twoshot_rows).

Per row: classify (classify.py), runs and links (runs.py), window lookup (lookup.py), chains and copy vote
(chains.py), column write (columns.py), then the vertical check of the row above (check.py) and, with
geometry, its depth (app.triangulate). Chains are row segments, so a chain of row y - 1 has all its vertical
votes once row y is labelled: the fused path needs one-row buffers and the last two rows of the chain maps,
no full-image codes or differences.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import (
    ChainMap,
    Classifier,
    FrameTables,
    Geometry,
    LabelScratch,
    LabelSettings,
    RowScratch,
    Runs,
    StripeCode,
)
from app.decode.fast.chains import NO_COPY, chain_ends, chain_nodes, copy_shift
from app.decode.fast.check import drop_chains, finish_row, row_votes
from app.decode.fast.classify import classify_row, classify_scratch
from app.decode.fast.columns import END_EXT, pixel_lines, write_chain
from app.decode.fast.lookup import window_labels
from app.decode.fast.runs import event_runs, event_scratch, pixel_runs, transitions
from app.triangulate import moebius_depth_row

MODES = ("events", "runs", "both")  # twoshot_rows' segmentation modes, by number


@njit(cache=True, nogil=True, error_model="numpy")
def row_scratch(n: int, W: int, n_copies: int) -> tuple[Runs, LabelScratch]:
    """The runs and labelling buffers of a row of W pixels with at most n runs (n >= W + 17). Runs, window
    positions and chain ends are int32: the compressed stores take sixteen to a register."""
    runs = Runs(
        np.empty(n, np.int32),
        np.empty(n, np.int32),
        np.empty(n, np.int32),
        np.zeros(n, np.bool_),
        np.zeros(n, np.float64),
        np.empty(n, np.int32),
    )
    seg_lines = np.empty(n, np.int64)
    px_lines = np.empty(n, np.int64)
    label = LabelScratch(
        np.zeros(n + 1, np.int32),
        np.empty(n, np.int32),
        np.zeros(n + 8, np.int32),
        np.empty(n, np.int32),
        np.empty(n, np.int8),
        np.empty(n, np.int8),
        np.empty(n, np.int8),
        np.empty(n, np.int32),
        np.empty(n, np.int32),
        np.empty(n, np.float64),
        np.empty(n, np.float64),
        np.empty(n, np.float64),
        np.empty(n, np.int32),
        np.empty(n, np.int32),
        np.empty(n, np.float64),
        np.empty(n, np.float64),
        np.zeros(max(n_copies, 1), np.int64),
        seg_lines,
        seg_lines.view(np.float32),
        px_lines,
        px_lines.view(np.float32),
        np.empty(n, np.int32),
        np.zeros(n + 1, np.int32),
    )
    return runs, label


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def label_row(
    y: int,
    nr: int,
    runs: Runs,
    scratch: LabelScratch,
    stripes: StripeCode,
    settings: LabelSettings,
    lo: np.ndarray,
    hi: np.ndarray,
    out: ChainMap,
    n_chains: int,
) -> int:
    """Windows -> confirmed labels -> chains -> interpolated columns of row y's nr runs into out (a ChainMap), the
    new chains numbered from n_chains; returns the next chain number. out.span[c] = (first, last) pixel chain c
    may write, when span has room for it; with room in out.npx, the chain's pixels and vertical votes are
    counted too (columns.write_chain)."""
    W = out.col.shape[1]
    k = settings.k
    row_first = n_chains  # this row's first chain
    if nr < k:
        return n_chains
    window_labels(nr, runs, stripes, settings, scratch)
    n_found = chain_ends(nr, runs, settings.period, scratch)
    sw = settings.stripe_width
    nv = scratch.nodes_v
    span = out.span
    for f in range(n_found):
        i0 = scratch.first_run[f]
        i1 = scratch.last_run[f]
        if i1 - i0 + 1 < k:
            continue
        nn = chain_nodes(i0, i1, runs, settings, scratch)
        if nn < 2:
            continue
        xa = runs.start[i0]  # the first and last whole pixel of the chain's end stripes
        xb = runs.end[i1]
        if xa < 0:
            xa = 0
        if xb > W - 1:
            xb = W - 1
        if xb < xa:
            continue
        shift = 0.0
        if settings.use_range:
            shift = copy_shift(y, nn, settings, lo, hi, scratch)
            if shift == NO_COPY:
                continue
        # pixels of the end stripes lie within one stripe of the outer edges; beyond is a guess
        lo_v = nv[0] - END_EXT * sw if settings.edges_mode else nv[0] - 0.5 * sw
        hi_v = nv[nn - 1] + END_EXT * sw if settings.edges_mode else nv[nn - 1] + 0.5 * sw
        nxp = xb - xa + 1
        pixel_lines(nn, xa, nxp, shift, scratch)
        lo_v = np.float32(lo_v + shift)
        hi_v = np.float32(hi_v + shift)
        write_chain(y, n_chains, row_first, xa, xb, lo_v, hi_v, scratch.px_halves, settings, lo, hi, out)
        if n_chains < span.shape[0]:
            span[n_chains, 0] = xa
            span[n_chains, 1] = xb
        n_chains += 1
    return n_chains


@njit(cache=True, nogil=True, error_model="numpy")
def label_rows(
    code: np.ndarray,
    feat: np.ndarray,
    noise: np.ndarray,
    events: bool,
    stripes: StripeCode,
    settings: LabelSettings,
    lo: np.ndarray,
    hi: np.ndarray,
    out_col: np.ndarray,
    out_chain: np.ndarray,
) -> int:
    """Rows -> sub-pixel projector columns (NaN = none) into out_col, chain ids into out_chain (both (H, W),
    initialised to NaN and -1). Returns the number of chains.

    Stripes come from pixel runs of equal code (events=False) or, for two-shot, from the zero crossings of each
    channel of feat, signed beyond the thresholds noise (events=True). lo/hi: per pixel, the projector columns
    the depth range allows (settings.use_range); the copy of a periodic sequence is chosen per chain as the one
    whose columns fall inside that interval for at least min_frac of its nodes, with no other copy close: else
    no value. No vertical check (see check.vertical_check).
    """
    H, W = code.shape
    m = feat.shape[2]
    n = (m + 1) * (2 * W + 8)
    runs, scratch = row_scratch(n, W, settings.n_copies)
    ev = event_scratch(m, n)
    no_count = np.empty(0, np.int32)
    out = ChainMap(out_col, out_chain, no_count, no_count, no_count, np.empty((0, 2), np.int32), np.zeros(1, np.int64))
    n_chains = 0
    trans = transitions(stripes.weights, stripes.link_ok, n)
    for y in range(H):
        if events:
            nr = event_runs(feat[y].T, noise[y].T, settings.gap_max, ev, runs)
        else:
            nr = pixel_runs(code[y], feat[y].T, stripes.weights, trans, settings.gap_max, runs)
        n_chains = label_row(y, nr, runs, scratch, stripes, settings, lo, hi, out, n_chains)
    return n_chains


@njit(cache=True, nogil=True, error_model="numpy")
def _chain_map(col, chain, cap, H):
    """A ChainMap over col and chain with per-chain counts and spans for cap chains, each written before it is
    read (no zeroing), and the rows' first chains."""
    return ChainMap(
        col,
        chain,
        np.empty(cap, np.int32),
        np.empty(cap, np.int32),
        np.empty(cap, np.int32),
        np.empty((cap, 2), np.int32),
        np.zeros(H + 1, np.int64),
    )


@njit(cache=True, nogil=True, error_model="numpy")
def twoshot_rows(
    f1: np.ndarray,
    f2: np.ndarray,
    tables: FrameTables,
    classifier: Classifier,
    stripes: StripeCode,
    settings: LabelSettings,
    mode: int,
    geometry: Geometry,
    col_e: np.ndarray,
    chain_e: np.ndarray,
    col_r: np.ndarray,
    chain_r: np.ndarray,
) -> tuple[int, int, int, int, int, int]:
    """The two-shot decoder fused row by row: classify a row into one-row buffers, label it from its zero
    crossings (col_e/chain_e) and/or from its pixel runs (col_r/chain_r), count the vertical agreement with the
    row above, and finish the row above (vertical check + merge, and its depth).

    Same result as twoshot_classify, label_rows, vertical_check and twoshot.merge_maps on full images. mode
    (MODES): 0 = the zero-crossing stripes alone ("events"), 1 = the pixel runs alone ("runs", into
    col_e/chain_e), 2 = both, the runs merged into the events (col_r/chain_r are used by mode 2 only; a value
    filled from the runs gets chain id runs chain + cap). The merged map is written into col_e/chain_e; the chain
    maps may hold the last R >= 2 rows only (row y at y % R), the column maps all. The maps need no
    initialisation. settings.tol <= 0 skips the vertical check. geometry.depth of the frames' size: each row is
    triangulated as soon as its columns are final (app.triangulate.moebius_depth_row, while in cache); a (0, 0)
    depth map for none. Returns (events chains, runs chains, events dropped, runs dropped, filled, clashes).
    """
    H, W = col_e.shape
    if chain_e.shape[0] < 2 or chain_e.shape[1] != W or (mode == 2 and (chain_r.shape[0] < 2 or chain_r.shape[1] != W)):
        raise ValueError("twoshot_rows: a chain map needs the frames' width and at least two rows")
    planes = geometry.planes
    if geometry.depth.shape == col_e.shape and (planes.shape[1] != H or planes.shape[2] != W):
        raise ValueError("twoshot_rows: the Moebius planes differ in size from the frames")
    m = classifier.unmix.shape[0]
    n = (m + 1) * (2 * W + 8)
    runs, label = row_scratch(n, W, settings.n_copies)
    scratch = RowScratch(classify_scratch(m, W, classifier.block), runs, event_scratch(m, n), label)
    cap = H * (n // settings.k + 2)  # at most this many chains: each holds k runs of a row
    ev = _chain_map(col_e, chain_e, cap, H)
    ru = _chain_map(col_r, chain_r, cap if mode == 2 else 1, H)  # the runs map of "both" only
    trans = transitions(stripes.weights, stripes.link_ok, n)
    stats = np.zeros(4, np.int64)  # dropped events, dropped runs, filled, clashes
    n_e, n_r = _rows((f1, f2), tables, classifier, stripes, trans, settings, scratch, geometry, ev, ru, mode, stats)
    return n_e, n_r, stats[0], stats[1], stats[2], stats[3]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _rows(frames, tables, classifier, stripes, trans, settings, scratch, geometry, ev, ru, mode, stats):
    """twoshot_rows' loop over the rows, without reference counting (its arrays all belong to the caller).
    Returns (n_e, n_r). The per-row stages are compiled with forceinline: LLVM inlines them into this loop."""
    f1, f2 = frames
    lo, hi = geometry.lo, geometry.hi
    ca = geometry.planes[0]
    cb = geometry.planes[1]
    cc = geometry.planes[2]
    depth = geometry.depth
    col_e, chain_e, col_r, chain_r = ev.col, ev.chain, ru.col, ru.chain
    want_depth = depth.shape == col_e.shape
    check = settings.tol > 0
    runs = scratch.runs
    H = col_e.shape[0]
    m = classifier.unmix.shape[0]
    fr = scratch.classify.rows[:m]
    tr = scratch.classify.rows[m:]
    code = scratch.classify.code
    n_e = 0
    n_r = 0
    for y in range(H):
        # the maps come uninitialised: each row is cleared just before it is labelled (while it is in cache)
        col_e[y] = np.nan
        chain_e[y % chain_e.shape[0]] = -1
        if mode == 2:
            col_r[y] = np.nan
            chain_r[y % chain_r.shape[0]] = -1
        # rows to prefetch while row y's differences are gathered, at addresses no hardware prefetcher guesses:
        # the geometry of row y (triangulated next time round), the column range of row y + 1 (read at its
        # nodes) and the column map's row y + 1 (cleared next time round); (1, 1) stand-ins when unused
        ahead = (
            (ca, min(y, ca.shape[0] - 1)),
            (cb, min(y, cb.shape[0] - 1)),
            (cc, min(y, cc.shape[0] - 1)),
            (lo, min(y + 1, lo.shape[0] - 1)),
            (hi, min(y + 1, hi.shape[0] - 1)),
            (col_e, min(y + 1, H - 1)),
        )
        classify_row(f1, f2, y, tables, classifier, scratch.classify, mode != 1, ahead)
        if mode == 1:
            nr = pixel_runs(code, fr, stripes.weights, trans, settings.gap_max, runs)
        else:
            nr = event_runs(fr, tr, settings.gap_max, scratch.events, runs)
        n_e = label_row(y, nr, runs, scratch.label, stripes, settings, lo, hi, ev, n_e)
        if mode == 2:
            nr = pixel_runs(code, fr, stripes.weights, trans, settings.gap_max, runs)
            n_r = label_row(y, nr, runs, scratch.label, stripes, settings, lo, hi, ru, n_r)
        ev.first[y + 1] = n_e
        ru.first[y + 1] = n_r
        if check:  # (the pixel counts the verdicts read come from label_row)
            row_votes(ev, y, settings.tol)
            if mode == 2:
                row_votes(ru, y, settings.tol)
        for yy in range(y - 1, y + 1 if y == H - 1 else y):
            if yy < 0:
                continue
            if mode == 2:
                finish_row(yy, ev, ru, check, settings.min_support, stats)
            elif check:  # one map: only the dropped chains' pixels change
                stats[0] += drop_chains(yy, ev, settings.min_support)
            if want_depth:
                moebius_depth_row(col_e, ca, cb, cc, yy, geometry.w0, geometry.w_span, depth)
    return n_e, n_r
