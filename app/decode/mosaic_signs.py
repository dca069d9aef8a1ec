"""Raw Bayer pairs (two-shot): the lacking channel's signs from the G edges as a pass of its own over the frames.

The model is app/decode/fast/lacking.py's (lacking_flips, per row). This pass swaps the two frames' values of
the lacking channel where the G edges say its sign is wrong (or moves them apart where the swap keeps its
unmixed sign, app/decode/fast/lacking_fill.py), before the decoder reads them: the specification
the fused decoder (which flips its own difference rows, fast.lacking.lacking_row) is tested against, and the
path of rigs decoded mirrored (TwoShotDecoder.decode), whose mirrored rows the model would see otherwise.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.fast.differences import differences
from app.decode.fast.lacking import lacking_channel, lacking_flips, lacking_scratch
from app.decode.fast.lacking_fill import exchanged, model_sign_codes


def lacking_signs(rgb1: np.ndarray, rgb2: np.ndarray, mosaic: str, decoder: object) -> tuple[np.ndarray, np.ndarray]:
    """The pair (rgb1, rgb2) (frames reconstructed from raw mosaics, in pattern order) with the lacking channel's
    values swapped between the frames where the G edges say its sign is wrong (new arrays; the inputs as they
    are for patterns other than G and one other channel). decoder: the pair's TwoShotDecoder (its tables and
    unmixing: the same differences the decoder takes)."""
    ig, cam, cx = lacking_channel(decoder.channels, mosaic)
    if cam < 0 or rgb1.ndim != 3:
        return rgb1, rgb2
    lin, dlin, packed = decoder.tables(rgb1.dtype)
    f1 = np.ascontiguousarray(rgb1)
    f2 = np.ascontiguousarray(rgb2)
    o1 = f1.copy()
    o2 = f2.copy()
    ta = np.float32(decoder.params.t_abs) * np.float32(0.5)  # (the noise floors the fused path's model reads)
    tables = (lin, dlin, packed, decoder.inverse(rgb1.dtype))
    _fix_pair(f1, f2, tables, decoder.unmix, ta, ig, cam, cx, o1, o2)
    return o1, o2


@njit(cache=True, nogil=True, error_model="numpy")
def _fix_pair(f1, f2, tables, unmix, ta, ig, cam, cx, o1, o2):
    """o1, o2: copies of f1, f2, changed where the lacking channel (camera channel cam, held by the columns of
    parity cx) gets the other sign; returns how many pixels changed. tables: (lin, dlin, packed) of the decoder
    (TwoShotDecoder.tables) and the response's inverse (TwoShotDecoder.inverse)."""
    lin, dlin, packed, inverse = tables
    H, W = f1.shape[0], f1.shape[1]
    rows = np.empty((4, W), np.float32)
    ahead = ((np.zeros((1, 1), np.float32), 0),)
    s = lacking_scratch(W)
    changed = 0
    for y in range(H):
        differences(f1, f2, y, lin, dlin, packed, unmix, ta, rows, ahead)
        n = lacking_flips(rows[ig], rows[1 - ig], rows[2 + ig], cx, s)
        for i in range(n):
            x = s.flips[i]
            a = (f1[y, x, 0], f1[y, x, 1], f1[y, x, 2])
            b = (f2[y, x, 0], f2[y, x, 1], f2[y, x, 2])
            a, b = exchanged(a, b, cam)
            a, b = model_sign_codes(a, b, cam, unmix[1 - ig], inverse, rows[1 - ig, x])
            o1[y, x, cam] = a[cam]
            o2[y, x, cam] = b[cam]
        changed += n
    return changed
