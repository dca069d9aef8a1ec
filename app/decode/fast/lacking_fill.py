"""Raw Bayer pairs (two-shot): the lacking channel's fill where the G-edge model gives it the other sign.

Where the sign model (lacking.py) says that the lacking channel's difference at a column lacking it has the
other sign, the two frames' values of that channel are exchanged. The decoder reads the channel unmixed:
camera B less the unmixing's share of the other camera channels (camera G's leak into B, mostly). Near a B
stripe edge the fill's camera difference is small (an interpolation between samples of opposite signs), and
where G is strong its leak term outweighs it, so the exchange leaves the unmixed sign as it was. There the
fill is replaced: the two frames' values of the lacking channel are moved apart about their mean linear value
so that the unmixed difference takes the model's sign at the magnitude the exchange left it. The fill is an
estimate, not a sample of the sensor, and the model measured right at many more of these pixels than the fill
(docs/performance.md, "The model's sign through the unmixing").

Both paths use these functions: the separate pass (app/decode/mosaic_signs.py) stores its codes into the frames,
the fused row loop (lacking.lacking_row) recomputes the pixel's differences from them, so both decode the same
maps bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.decode.response_inverse import ResponseInverse, nearest_code


@njit(cache=True, nogil=True, error_model="numpy")
def model_sign_codes(a: tuple, b: tuple, cam: int, row: np.ndarray, response: ResponseInverse, before: float) -> tuple:
    """(a, b): a pixel's codes (c0, c1, c2) in frame 1 and frame 2, their lacking camera channel cam already
    exchanged; row: the unmixing row (3,) of the lacking pattern channel; response: the camera response and its
    inverse (response_inverse of the decoder's table); before: that pattern channel's unmixed difference before
    the exchange. Returns (a, b) with the lacking channel's codes moved so that the unmixed difference (lin[b] -
    lin[a] unmixed by row) has the sign opposite to before's, at the magnitude the exchange left, where the
    exchange kept before's sign; else as given (also where before has no sign, or the channel does not enter the
    row); codes as int64."""
    a = (np.int64(a[0]), np.int64(a[1]), np.int64(a[2]))
    b = (np.int64(b[0]), np.int64(b[1]), np.int64(b[2]))
    lin = response.lin
    e0 = np.float64(lin[0, b[0]]) - np.float64(lin[0, a[0]])
    e1 = np.float64(lin[1, b[1]]) - np.float64(lin[1, a[1]])
    e2 = np.float64(lin[2, b[2]]) - np.float64(lin[2, a[2]])
    after = row[0] * e0 + row[1] * e1 + row[2] * e2
    kept = (before > 0 and after > 0) or (before < 0 and after < 0)
    if not kept or row[cam] == 0:
        return a, b
    own = e0 if cam == 0 else (e1 if cam == 1 else e2)
    wanted = own - 2.0 * after / row[cam]  # the camera difference whose unmixed value is -after
    mean = 0.5 * (np.float64(lin[cam, a[cam]]) + np.float64(lin[cam, b[cam]]))
    code_a = _code(response, cam, mean - 0.5 * wanted)
    code_b = _code(response, cam, mean + 0.5 * wanted)
    if cam == 0:
        return (code_a, a[1], a[2]), (code_b, b[1], b[2])
    if cam == 1:
        return (a[0], code_a, a[2]), (b[0], code_b, b[2])
    return (a[0], a[1], code_a), (b[0], b[1], code_b)


@njit(inline="always")
def exchanged(a: tuple, b: tuple, cam: int) -> tuple:
    """The codes (c0, c1, c2) of a pixel in both frames with camera channel cam exchanged between them."""
    if cam == 0:
        return (b[0], a[1], a[2]), (a[0], b[1], b[2])
    if cam == 1:
        return (a[0], b[1], a[2]), (b[0], a[1], b[2])
    return (a[0], a[1], b[2]), (b[0], b[1], a[2])


@njit(inline="always")
def _code(response, c, value):
    """The code of channel c at linear value `value` (response_inverse.nearest_code), int64."""
    steps = response.codes.shape[0] // 3  # (the entries of each channel's inverse)
    top = response.lin.shape[1] - 1
    last = np.float32(steps - 2)
    code = nearest_code(np.float32(value), c * steps, response.codes, response.scale, response.root, last, top)
    return np.int64(code)
