"""Compiled per-frame kernels of the virtual rig (numba, one core).

The frame path is memory-bound: separate numpy/OpenCV passes each walk the whole image and
allocate a fresh buffer (page faults dominate at 1280x1024). Two fused passes do the work:
`light_to_linear` (pattern lookup, reflectance, ambient, crosstalk) before the lens blur and
`sensor` (noise, clipping, quantisation, response LUT) after it.
"""

from __future__ import annotations

import numba
import numpy as np

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)


@numba.njit(cache=True, nogil=True)
def light_to_linear(
    light: np.ndarray,  # (Hp, Wp, 3) float32 projector light
    maps: np.ndarray,  # (H, W, 2) int16 nearest projector pixel (x, y); -1 = not lit
    coef: np.ndarray,  # (H, W, 3) float32 exposure * (albedo * shading + specular)
    amb: np.ndarray,  # (H, W, 3) float32 exposure * albedo * ambient
    mix: np.ndarray,  # (3, 3) float32 crosstalk
    out: np.ndarray,  # (H, W, 3) float32
) -> None:
    h, w = maps.shape[0], maps.shape[1]
    m00, m01, m02 = mix[0, 0], mix[0, 1], mix[0, 2]
    m10, m11, m12 = mix[1, 0], mix[1, 1], mix[1, 2]
    m20, m21, m22 = mix[2, 0], mix[2, 1], mix[2, 2]
    for y in range(h):
        for x in range(w):
            u = maps[y, x, 0]
            v = maps[y, x, 1]
            r = amb[y, x, 0]
            g = amb[y, x, 1]
            b = amb[y, x, 2]
            if u >= 0:
                r += coef[y, x, 0] * light[v, u, 0]
                g += coef[y, x, 1] * light[v, u, 1]
                b += coef[y, x, 2] * light[v, u, 2]
            out[y, x, 0] = m00 * r + m01 * g + m02 * b
            out[y, x, 1] = m10 * r + m11 * g + m12 * b
            out[y, x, 2] = m20 * r + m21 * g + m22 * b


@numba.njit(cache=True, nogil=True, fastmath=True)
def sensor(
    img: np.ndarray,  # (N,) float32 linear signal, 1 = full scale
    bank: np.ndarray,  # (M,) float32 standard normal samples (M >= N + start)
    start: int,
    use_noise: bool,
    inv_full_well: float,
    read_var: float,
    lut: np.ndarray,  # (65536,) response: 16-bit linear code -> output value
    out: np.ndarray,  # (N,) uint8 or uint16
) -> None:
    k = np.float32(inv_full_well)
    r2 = np.float32(read_var)
    scale = np.float32(65535.0)
    half = np.float32(0.5)
    top = np.float32(65535.0)
    zero = np.float32(0.0)
    n = img.shape[0]
    if use_noise:
        z = bank[start : start + n]
        for i in range(n):
            v = img[i]
            v += np.sqrt(max(v, zero) * k + r2) * z[i]
            c = min(max(v * scale + half, zero), top)
            out[i] = lut[np.int32(c)]
    else:
        for i in range(n):
            c = min(max(img[i] * scale + half, zero), top)
            out[i] = lut[np.int32(c)]


@numba.njit(cache=True, nogil=True)
def _affine(X: np.ndarray, M: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    out = np.empty((X.shape[0], 3))
    for i in range(X.shape[0]):
        x0 = X[i, 0] - before[0]
        x1 = X[i, 1] - before[1]
        x2 = X[i, 2] - before[2]
        for k in range(3):
            out[i, k] = x0 * M[0, k] + x1 * M[1, k] + x2 * M[2, k] + after[k]
    return out


_ZERO3 = np.zeros(3)


def affine3(
    X: np.ndarray, M: np.ndarray, before: np.ndarray | None = None, after: np.ndarray | None = None
) -> np.ndarray:
    """(X - before) @ M + after for (N, 3) points, one thread.

    numpy's matmul hands (N, 3) @ (3, 3) to a multi-threaded BLAS, which is ten times slower
    than this loop on a busy 2-core machine.
    """
    X = np.ascontiguousarray(X, np.float64).reshape(-1, 3)
    b = _ZERO3 if before is None else np.ascontiguousarray(before, np.float64).reshape(3)
    a = _ZERO3 if after is None else np.ascontiguousarray(after, np.float64).reshape(3)
    return _affine(X, np.ascontiguousarray(M, np.float64), b, a)


_WARM: set = set()


def warm_up(out_dtype: np.dtype) -> None:
    """Compile (or load from the cache) the frame kernels for these types now, on tiny arrays,
    so the first real frame (inside a camera grab with a timeout) does not pay for it."""
    key = np.dtype(out_dtype).str
    if key in _WARM:
        return
    f3 = np.zeros((2, 2, 3), np.float32)
    light_to_linear(f3, np.full((2, 2, 2), -1, np.int16), f3, f3, np.eye(3, dtype=np.float32), f3.copy())
    lut = np.zeros(65536, out_dtype)
    sensor(f3.reshape(-1), np.zeros(16, np.float32), 0, True, 1e-4, 1e-5, lut, np.zeros(12, out_dtype))
    _WARM.add(key)
