"""Chains (paper section 3): maximal stretches of a row's labelled runs, each linked to the next with the next
label; their nodes (sub-pixel stripe edges or centres, with their projector columns) and the copy vote.

The nodes must increase along the row; smoothing replaces each by a local line fit over +-smooth neighbours
(surfaces are smooth within a chain). A periodic sequence repeats across the projector: with a depth range,
each node votes for the copies that put its column inside its pixel's allowed interval, and the chain takes the
clear winner, else no value.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import LabelScratch, LabelSettings, Runs
from app.decode.fast.lacking_edges import lacking_edges
from app.decode.fast.lookup import wrap
from app.decode.primitives import append_sparse, gather

NO_COPY = -1.0  # copy_shift's answer when no copy wins


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def chain_ends(nr: int, runs: Runs, period: int, scratch: LabelScratch) -> int:
    """The chains among the row's nr labelled runs: chain f covers runs scratch.first_run[f] ..
    scratch.last_run[f]; returns how many. Marked in vectorised loops, then listed by append_sparse."""
    lab = scratch.label
    link = runs.link
    cont = scratch.linked_next
    starts = scratch.starts
    ends = scratch.ends
    per = np.int32(period)
    if nr < 1:
        return 0
    # no condition and no index of unknown sign in the loops (a conditional load, or numba's negative-index fix
    # of cont[i - 1], makes the vectorised loop's loads masked loads and selects); the last run continues nothing
    lab1 = lab[1:]
    for i in range(nr - 1):
        # int32 throughout, eight to a vector (numba widens int32 arithmetic to int64)
        li = lab[i]
        cont[i] = link[i] & (li >= 0) & (lab1[i] == wrap(np.int32(li + 1), per))
    cont[nr - 1] = 0
    for i in range(nr):
        ends[i] = (lab[i] >= 0) & (cont[i] == 0)
    starts[0] = lab[0] >= 0
    starts1 = starts[1:]
    for i in range(nr - 1):
        starts1[i] = (lab1[i] >= 0) & (cont[i] == 0)
    # a few chains in a row's hundreds of runs: sparse flags
    n_found = append_sparse(starts, nr, scratch.first_run)
    append_sparse(ends, nr, scratch.last_run)
    return n_found


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def increasing(x: np.ndarray, n: int) -> None:
    """x[:n] made strictly increasing in place: a value not above the one before becomes that one + 1e-3.
    A vectorised test first: the values nearly always increase already, and the fix is sequential. (In place:
    a copy from an array to itself defeats the compiler's overlap check.)"""
    ok = True
    for r in range(1, n):
        ok &= x[r] > x[r - 1]
    if ok:
        return
    for r in range(1, n):
        x[r] = x[r - 1] + 1e-3 if x[r] <= x[r - 1] else x[r]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def chain_nodes(i0: int, i1: int, runs: Runs, settings: LabelSettings, scratch: LabelScratch) -> int:
    """The nodes of the chain of runs i0..i1 into scratch.nodes_x (pixel) and nodes_v (projector column, before
    the copy's shift): stripe edges (edges_mode) or centres, made increasing and smoothed; returns how many. A raw
    mosaic's lacking channel has its edges placed from the G edges first (lacking_edges.py).

    The chain's runs are read through views from i0 (an index i0 + q of unknown sign gets numba's negative-index
    fix per element, which turns the loads into gathers); the values are small multiples of 0.5, so the float
    sums equal the integer products exactly. Integers reach float through int32: int64 -> float has no vector
    instruction before AVX-512."""
    nx = scratch.nodes_x
    nv = scratch.nodes_v
    sw = settings.stripe_width
    swf = np.float64(sw)
    base = scratch.label[i0]
    if settings.edges_mode:
        nn = i1 - i0
        e_c = runs.edge[i0:]
        v0 = (base + 1) * sw - 0.5
        for q in range(nn):
            nx[q] = e_c[q]
            nv[q] = v0 + np.int32(q) * swf
    else:
        nn = i1 - i0 + 1
        rs_c = runs.start[i0:]
        re_c = runs.end[i0:]
        v0 = base * sw + 0.5 * (sw - 1)
        for q in range(nn):
            nx[q] = 0.5 * np.int32(rs_c[q] + re_c[q])
            nv[q] = v0 + np.int32(q) * swf
    if nn < 2:
        return nn  # no segment to interpolate on (only with a window of k < 3 in the edges mode)
    increasing(nx, nn)
    if settings.lacking_bit != 0 and settings.edges_mode:  # (frames reconstructed from a raw mosaic)
        lacking_edges(nx, nn, runs.code[i0:], settings.lacking_bit, sw)
        increasing(nx, nn)
    smooth = settings.smooth
    if smooth > 0 and nn > 2 * smooth:
        _smooth_nodes(nx, nn, smooth, scratch.smoothed)
        increasing(nx, nn)
    return nn


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def _smooth_nodes(nx, nn, smooth, sm):
    """Each of the nn nodes nx replaced by a straight-line fit x(v) over +-smooth nodes (sm: scratch).

    The nodes' v are equally spaced (one stripe apart), so the fit is a fixed linear filter: with window offsets
    q = 0..n-1 (n = 2 * smooth + 1) and the node at offset t, the fitted x is
    sum_q x_q * (1 / n + (q - smooth) * (t - smooth) / S), S = sum_q (q - smooth)**2. Interior nodes have
    t = smooth: every weight is 1 / n (the same sum, fewer operations)."""
    nw = 2 * smooth + 1
    S = 0.0
    for q in range(nw):
        S += (q - smooth) * (q - smooth)
    inv_nw = 1.0 / nw
    if smooth == 2:
        # the usual +-2 written out, read through views from each offset (no negative-index fix: see chain_nodes)
        x0 = nx[0:]
        x1 = nx[1:]
        x2 = nx[2:]
        x3 = nx[3:]
        x4 = nx[4:]
        s2 = sm[2:]
        for q in range(nn - 4):
            acc = 0.0 + x0[q] * inv_nw + x1[q] * inv_nw + x2[q] * inv_nw
            s2[q] = acc + x3[q] * inv_nw + x4[q] * inv_nw
    else:
        for r in range(smooth, nn - smooth):
            acc = 0.0
            for q in range(nw):
                acc += nx[r - smooth + q] * inv_nw
            sm[r] = acc
    # the end nodes fit the first or last window
    for e in range(2 * smooth):
        r = e if e < smooth else nn - 2 * smooth + e
        a0 = 0 if r < smooth else nn - nw
        tc = (r - a0 - smooth) / S
        xs = nx[a0:]
        acc = 0.0
        for q in range(nw):
            acc += xs[q] * (1.0 / nw + (q - smooth) * tc)
        sm[r] = acc
    for r in range(nn):
        nx[r] = sm[r]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def copy_shift(
    y: int, nn: int, settings: LabelSettings, lo: np.ndarray, hi: np.ndarray, scratch: LabelScratch
) -> float:
    """The copy vote of a chain of nn nodes in row y (allowed columns lo[y], hi[y]): the winning copy's shift
    (copy index * period * stripe width), NO_COPY without a clear winner (fewer than min_frac of the nodes, or
    a runner-up with more than half its votes).

    Node r votes for copies q >= q0 (the first whose column reaches lo) while v + q span <= hi: the pixels'
    range ends gathered first, then each copy's count as a vectorised sum over the nodes."""
    nx = scratch.nodes_x
    nv = scratch.nodes_v
    W = lo.shape[1]
    n_copies = settings.n_copies
    copy_span = settings.period * settings.stripe_width
    inv_span = 1.0 / copy_span  # a multiply, not a division (exact for the usual power-of-2 span)
    pw = settings.proj_width - 0.5
    xr = scratch.node_px
    wmax = np.float64(W - 1)
    for r in range(nn):
        # clamped in float (NaN -> 0), then converted to int32, which equals clamping int(): float -> int64 has
        # no vector instruction before AVX-512
        t = nx[r] + 0.5
        t = t if t > 0.0 else 0.0
        xr[r] = np.int32(t if t < wmax else wmax)
    glo = scratch.node_lo
    ghi = scratch.node_hi
    gather(glo, lo[y], xr, nn)
    gather(ghi, hi[y], xr, nn)
    q0 = scratch.first_copy
    for r in range(nn):
        v = nv[r]
        hv = ghi[r]
        ghi[r] = pw if hv > pw else hv
        # clamped in float: int() of NaN or of values past int64 is undefined (x86 gives INT64_MIN)
        qf = np.ceil((glo[r] - v) * inv_span)
        q0[r] = np.int32(min(qf, n_copies)) if qf > 0.0 else np.int32(0)
    votes = scratch.votes
    if n_copies <= 4:
        # the usual few copies counted in one pass over the nodes
        c0 = 0
        c1 = 0
        c2 = 0
        c3 = 0
        for r in range(nn):
            v = nv[r]
            hv = ghi[r]
            qr = q0[r]
            c0 += (qr <= 0) & (v <= hv)
            c1 += (qr <= 1) & (v + copy_span <= hv)
            c2 += (qr <= 2) & (v + 2 * copy_span <= hv)
            c3 += (qr <= 3) & (v + 3 * copy_span <= hv)
        votes[0] = c0
        if n_copies > 1:
            votes[1] = c1
        if n_copies > 2:
            votes[2] = c2
        if n_copies > 3:
            votes[3] = c3
    else:
        for q in range(n_copies):
            cnt = 0
            offset = q * copy_span
            for r in range(nn):
                cnt += (q >= q0[r]) & (nv[r] + offset <= ghi[r])
            votes[q] = cnt
    best_q = -1
    best_n = 0
    second_n = 0
    for q in range(n_copies):
        cnt = votes[q]
        if cnt > best_n:
            second_n = best_n
            best_n = cnt
            best_q = q
        elif cnt > second_n:
            second_n = cnt
    if best_q < 0 or best_n < settings.min_frac * nn or second_n > 0.5 * best_n:
        return NO_COPY
    return float(best_q * copy_span)
