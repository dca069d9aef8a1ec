"""Raw Bayer pairs (two-shot): where the lacking channel's stripe edges lie, from the G edges.

A Bayer sensor samples B (or R) in every other column. Inside a run of constant G the two-shot code flips B at
every stripe edge, so B's period there is two stripes; where a stripe is narrower than ALIASED_WIDTH camera
pixels that period is near B's Nyquist period (4 pixels) and B's own samples cannot place its edges: at a column
lacking B the reconstruction's fill (app/decode/mosaic.py) is a blend of both neighbours, so each edge's zero
crossing is pulled towards the lacking column by a few tenths of a pixel, so edges of one column parity move
left and the other's right (docs/performance.md, "Single-chip colour cameras"). G is sampled in every column
and its edges are placed at full resolution; between two of them the n stripes have equal width (a surface is
smooth over a few stripes), so a lacking channel's edge there is the interpolation of the two G edges by its
stripe count. A chain's lacking edges beyond its first or last G edge (where the nearest pair of G edges spans
narrow stripes too) have no G edge on their far side: they are placed on from that outer G edge at the stripe
step of the chain's G edges within END_NODES nodes of it (their least-squares slope over the node index), which
the surface keeps nearly constant over a few stripes, while an aliased edge measured alone is off by up to a
pixel where the chain meets the image's edge or a hole. With fewer than three G edges there, they keep their
measured position moved by the mean offset the interpolated ones had from their own measurements, signed by
parity: the pull the chain's blur and width give (which parity moves which way the mean learns with its sign).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)

ALIASED_WIDTH = 2.4  # camera pixels per stripe below which the lacking channel's edges come from the G edges
END_NODES = 24  # a chain's end edges take the stripe step of its G edges among this many nodes from its outer one
NO_LACKING_EDGES = 0  # LabelSettings.lacking_bit of frames that are not a raw mosaic's


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def lacking_edges(nx: np.ndarray, nn: int, codes: np.ndarray, bit: int, stripe_width: int) -> None:
    """The chain's nn edge nodes nx (increasing; edge q between the runs of codes[q] and codes[q + 1]) with the
    lacking channel's edges (those flipping code bit `bit`) placed from the G edges where the stripes between
    two G edges are narrower than ALIASED_WIDTH pixels (see the module's text), in place."""
    limit = ALIASED_WIDTH * stripe_width  # (camera px per node step: one stripe of stripe_width columns)
    offset = 0.0
    n_offsets = 0
    first_g = -1
    last_g = -1
    first_wide = False  # whether the first and the last pair of G edges span wide stripes
    last_wide = False
    for q in range(nn):
        if (codes[q] ^ codes[q + 1]) == bit:
            continue
        if last_g < 0:
            first_g = q
        else:
            x0 = nx[last_g]
            step = (nx[q] - x0) / (q - last_g)
            last_wide = step >= limit
            if first_g == last_g:
                first_wide = last_wide
            if not last_wide:  # (every edge between two G edges flips the other channel)
                for r in range(last_g + 1, q):
                    x = x0 + (r - last_g) * step
                    offset += _parity_sign(nx[r]) * (x - nx[r])
                    nx[r] = x
                n_offsets += q - last_g - 1
        last_g = q
    if n_offsets == 0:  # (no G edges, or no lacking edge between two: nothing to learn the pull from)
        return
    mean = offset / n_offsets
    if not first_wide:
        step = _g_step(nx, codes, bit, first_g, min(first_g + END_NODES, nn))
        for q in range(first_g):
            nx[q] = nx[first_g] - (first_g - q) * step if step > 0 else nx[q] + _parity_sign(nx[q]) * mean
    if not last_wide:
        step = _g_step(nx, codes, bit, max(last_g - END_NODES + 1, 0), last_g + 1)
        for q in range(last_g + 1, nn):
            nx[q] = nx[last_g] + (q - last_g) * step if step > 0 else nx[q] + _parity_sign(nx[q]) * mean


@njit(cache=True, nogil=True, inline="always")
def _g_step(nx, codes, bit, q0, q1):
    """The least-squares slope of the G edges' positions over their node index among nodes q0..q1 - 1 (camera
    pixels per node); 0 with fewer than three of them (or a slope that is not positive)."""
    n = 0
    sq = 0.0
    sx = 0.0
    sqq = 0.0
    sqx = 0.0
    x0 = nx[q0]
    for q in range(q0, q1):
        if (codes[q] ^ codes[q + 1]) != bit:
            d = np.float64(q - q0)
            x = nx[q] - x0
            n += 1
            sq += d
            sx += x
            sqq += d * d
            sqx += d * x
    if n < 3:
        return 0.0
    den = n * sqq - sq * sq
    return max((n * sqx - sq * sx) / den, 0.0) if den > 0 else 0.0


@njit(cache=True, nogil=True, inline="always")
def _parity_sign(x):
    """+1 for an edge whose left column (floor(x)) is even, -1 for odd: the fill's pull has one sign per parity."""
    return 1.0 if (np.int64(np.floor(x)) & 1) == 0 else -1.0
