"""Raw Bayer pairs (two-shot): the lacking channel's leak into G removed at its stripes' amplitude.

Camera G sees some of the projected lacking channel (B, say), which the unmixing removes from the G pattern
channel as U[G, B] times B's camera difference at the pixel. At the columns lacking B that difference is the
reconstruction's interpolation across the row (app/decode/mosaic.py), across stripes of alternating sign: where
a stripe is about two camera pixels wide the interpolation shrinks B towards zero (aliasing), so the unmixing
leaves part of B's leak in G, and where G is weak beside a strong B (magenta, blue surfaces) G's sign at those
columns follows B's stripes rather than G's (docs/performance.md, "The lacking channel's leak into G").

The two-shot levels are saturated minima and maxima, so a stripe's difference reaches the local amplitude, which
the B columns either side sample exactly: the B difference the G pattern channel is unmixed with is raised to
the smaller of its two neighbours' magnitudes, keeping its sign (the sign model's, lacking.py, where it flipped
the pixel). The B pattern channel keeps the interpolation: a raised magnitude would make a wrong sign
confident there (yellow surfaces: a weak B). Mirrored rows (the camera's columns reversed) work alike, with the
parity of the mirrored columns.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.bundles import NO_LEAK, Classifier, ClassifyScratch, FrameTables
from app.decode.fast.lacking import lacking_channel


def leak_channel(channels: str, mosaic: str | None, mirrored: bool) -> tuple[int, int, int, int]:
    """Classifier.leak of a two-shot pattern's channels seen through a raw mosaic: lacking_channel's (pattern
    channel of G, camera channel of the other, column parity holding it) and 1 if the rows are decoded
    mirrored; NO_LEAK where lacking_channel has none."""
    ig, cam, cx = lacking_channel(channels, mosaic)
    if cam < 0:
        return NO_LEAK
    return ig, cam, cx, int(bool(mirrored))


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
def leak_row(
    f1: np.ndarray,
    f2: np.ndarray,
    y: int,
    tables: FrameTables,
    classifier: Classifier,
    scratch: ClassifyScratch,
    n_flips: int,
) -> None:
    """Row y's G pattern channel (scratch.rows[ig], after the sign model) with the lacking channel's leak removed
    at the amplitude of its neighbouring columns, at the columns lacking it; nothing without classifier.leak.
    n_flips: the pixels the sign model flipped (scratch.lacking.flips[:n_flips]), whose camera difference is
    the one their new values give (scratch.lacking.flipped_c, lacking.lacking_row)."""
    ig, cam, cx, mirrored = classifier.leak
    if cam < 0:
        return
    s = scratch.lacking
    e = s.camera_c
    W = e.shape[0]
    lc = tables.lin[cam]
    a = f1[y, :, cam]
    b = f2[y, :, cam]
    for x in range(W):
        e[x] = lc[b[x]] - lc[a[x]]
    for i in range(n_flips):
        e[s.flips[i]] = s.flipped_c[i]
    held = (W - 1 - cx) & 1 if mirrored else cx  # (the parity of the columns holding the channel, in these rows)
    k = classifier.unmix[ig, cam]
    g = scratch.rows[ig]
    for x in range(1, W - 1):
        v = e[x]
        amplitude = min(abs(e[x - 1]), abs(e[x + 1]))
        raised = (np.float32(v > 0) - np.float32(v < 0)) * amplitude
        lacks = (x & 1) != held
        # (a select over every column rather than a loop over every other one: the compiler vectorises it)
        g[x] = g[x] + k * (raised - v) if lacks & (abs(v) < amplitude) else g[x]
