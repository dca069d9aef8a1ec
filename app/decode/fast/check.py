"""The vertical check (paper section 5) and the merge of two maps.

A chain survives where the rows above and below confirm it: every labelled neighbour (y +- 1, same x) within tol
projector px agrees, any other disagrees; it needs more agreements than disagreements and at least min_support
agreements per pixel. A two-shot window sequence is any walk of one-bit changes, so a chain made of noise
(shadow, black surface) matches the sequence by chance far too easily, but it never lines up with the rows next
to it. The fused decoder counts the votes row by row (row_votes, and columns.write_chain while writing) and
finishes a row once the row below it is labelled.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import ChainMap


@njit(cache=True, nogil=True, inline="always")
def _unconfirmed(agree, disagree, npx, min_support):
    """The vertical check's verdict on a chain: no more agreeing than disagreeing vertical neighbours, or
    fewer than min_support agreeing ones per pixel."""
    return disagree >= agree or agree < min_support * npx


@njit(cache=True, nogil=True, error_model="numpy")
def vertical_check(out_col: np.ndarray, out_chain: np.ndarray, n_chains: int, tol: float, min_support: float) -> int:
    """Keep a chain only where the rows above and below confirm it (see the module docstring), on whole maps
    (H, W); returns how many chains it dropped."""
    H, W = out_col.shape
    nc = max(n_chains, 1)
    agree = np.zeros(nc, np.int32)
    disagree = np.zeros(nc, np.int32)
    npx = np.zeros(nc, np.int32)
    for y in range(H):
        for x in range(W):
            c = out_chain[y, x]
            if c < 0:
                continue
            npx[c] += 1
            v = out_col[y, x]
            for dy in (-1, 1):
                yy = y + dy
                if yy < 0 or yy >= H:
                    continue
                if out_chain[yy, x] < 0:
                    continue
                if abs(out_col[yy, x] - v) <= tol:
                    agree[c] += 1
                else:
                    disagree[c] += 1
    drop = np.zeros(nc, np.bool_)
    dropped = 0
    for c in range(n_chains):
        if _unconfirmed(agree[c], disagree[c], npx[c], min_support):
            drop[c] = True
            dropped += 1
    if dropped:
        for y in range(H):
            for x in range(W):
                c = out_chain[y, x]
                if c >= 0 and drop[c]:
                    out_col[y, x] = np.nan
                    out_chain[y, x] = -1
    return dropped


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def row_votes(out: ChainMap, y: int, tol: float) -> None:
    """Add the vertical agreement between rows y - 1 and y of out (a ChainMap) to the chains of row y - 1
    (columns.write_chain counted the chains of row y, their pixels and their votes against row y - 1).

    Walks each chain's span with the counts in registers, then adds them once per chain (a per-pixel increment
    of a per-chain counter would chain every pixel through memory)."""
    if y == 0:
        return
    col, chain, agree, disagree, _, span, first = out
    cy = y % chain.shape[0]
    cu = (y - 1) % chain.shape[0]
    tol32 = np.float32(tol)  # compared with float32 differences without a conversion per pixel
    for c in range(first[y - 1], first[y]):
        # the chain id and counts in int32, the lanes of the int32 ids and float32 columns (numba widens int32
        # arithmetic to int64)
        c32 = np.int32(c)
        ag = np.int32(0)
        dg = np.int32(0)
        for xi in range(span[c, 0], span[c, 1] + 1):
            x = np.uint64(xi)  # unsigned: no negative-index fix per pixel (which turns the loads into gathers)
            pair = (chain[cu, x] == c32) & (chain[cy, x] >= 0)
            close = abs(col[y - 1, x] - col[y, x]) <= tol32
            ag = np.int32(ag + (pair & close))
            dg = np.int32(dg + (pair & (not close)))
        agree[c] += ag
        disagree[c] += dg


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def drop_chains(y: int, out: ChainMap, min_support: float) -> int:
    """vertical_check's verdict on the chains of row y of out, which have all their votes; returns how many it
    dropped."""
    col, chain, agree, disagree, npx, span, first = out
    cy = y % chain.shape[0]
    dropped = 0
    for c in range(first[y], first[y + 1]):
        if _unconfirmed(agree[c], disagree[c], npx[c], min_support):
            dropped += 1
            for x in range(span[c, 0], span[c, 1] + 1):
                if chain[cy, x] == c:
                    col[y, x] = np.nan
                    chain[cy, x] = -1
    return dropped


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def finish_row(y: int, ev: ChainMap, ru: ChainMap, check: bool, min_support: float, stats: np.ndarray) -> None:
    """Row y of the maps ev (events) and ru (runs) has all its vertical votes: drop its unconfirmed chains
    (check), then merge ru into ev: a value of one where the other has none, none where both differ by more than
    0.5 px. A value taken from ru gets chain id (runs chain + cap), cap = ev's chain capacity. stats: dropped
    events, dropped runs, filled, clashes (added to)."""
    col_e, chain_e, col_r, chain_r = ev.col, ev.chain, ru.col, ru.chain
    npx_e, npx_r = ev.npx, ru.npx
    cap = ev.npx.shape[0]
    W = col_e.shape[1]
    ce_y = y % chain_e.shape[0]
    cr_y = y % chain_r.shape[0]
    if check:
        # a chain is dropped by marking its pixel count negative (read below)
        for c in range(ev.first[y], ev.first[y + 1]):
            if _unconfirmed(ev.agree[c], ev.disagree[c], npx_e[c], min_support):
                npx_e[c] = -1
                stats[0] += 1
        for c in range(ru.first[y], ru.first[y + 1]):
            if _unconfirmed(ru.agree[c], ru.disagree[c], npx_r[c], min_support):
                npx_r[c] = -1
                stats[1] += 1
    for x in range(W):
        ce = chain_e[ce_y, x]
        cr = chain_r[cr_y, x]
        ok_e = ce >= 0 and npx_e[ce] >= 0
        ok_r = cr >= 0 and npx_r[cr] >= 0
        if ok_e:
            if ok_r and abs(col_e[y, x] - col_r[y, x]) > 0.5:
                col_e[y, x] = np.nan
                chain_e[ce_y, x] = -1
                stats[3] += 1
        elif ok_r:
            col_e[y, x] = col_r[y, x]
            chain_e[ce_y, x] = cr + cap
            stats[2] += 1
        elif ce >= 0:
            col_e[y, x] = np.nan
            chain_e[ce_y, x] = -1
