"""Motion: the older frame of a two-shot pair, repaired where the scene moved since the frame before it.

A two-shot pair decodes from the sign of frame2 - frame1, which holds only while the scene is still. Where the
newest frame differs from the previous frame of the same pattern (two frames earlier) by more than noise and a
share of the local stripe contrast, the scene moved: there the older frame is replaced by the newest frame's own
inverse about its local envelope, lin(older') = hi + lo - lin(newest), with hi and lo the largest and smallest
linear value of either frame within `radius` pixels along the row. The pair's difference is then twice the newest
frame's distance from its local midpoint: the newest frame decodes alone, as the one-shot code it is, while still
pixels keep the pair's robustness to surface colour and ambient light. Elsewhere the older frame is left as it was,
bit for bit, so a still scene decodes exactly as without this stage.

`app/decode/motion.py` holds the parameters and a plain numpy statement of the same computation (the tests
compare both).
"""

from __future__ import annotations

import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)


@njit(cache=True, nogil=True, error_model="numpy")
def repair_older(
    newest_lin: np.ndarray,
    previous_lin: np.ndarray,
    hi: np.ndarray,
    lo: np.ndarray,
    slopes: np.ndarray,
    older: np.ndarray,
    inverse: np.ndarray,
    grid: np.ndarray,
    watched: np.ndarray,
    limits: np.ndarray,
    spread: int,
    out: np.ndarray,
) -> int:
    """Write the repaired older frame into out (the older frame's shape and dtype) and return the moving pixels.

    newest_lin, previous_lin: (H, W, 3) float32 linear values of the newest frame and of the frame before the older
    one (it saw the newest frame's pattern); hi, lo: the largest and smallest linear value of the newest or the older
    frame within the envelope window along the row; slopes: the two frames' noise slopes summed (linear per raw 8-bit
    step). inverse, grid: linear value -> nearest raw level per channel (app.decode.motion.inverse_table). watched:
    the camera channels (int64) whose change marks motion (the pattern's). limits: float32 (share of the local
    contrast, multiple of the noise slopes, floor in linear 8-bit units) a change must exceed. spread: how far along
    the row a moving pixel's mark reaches."""
    H, W, C = newest_lin.shape
    rel, noise_k, floor = limits[0], limits[1], limits[2]
    changed = np.empty(W, np.uint8)
    moving = np.empty(W, np.uint8)
    n_moving = 0
    for y in range(H):
        out[y] = older[y]
        n, p, h, l, s = newest_lin[y], previous_lin[y], hi[y], lo[y], slopes[y]
        changed[:] = 0
        for i in range(watched.shape[0]):
            c = watched[i]
            for x in range(W):
                limit = max(rel * (h[x, c] - l[x, c]), noise_k * s[x, c], floor)
                changed[x] |= abs(n[x, c] - p[x, c]) > limit
        # a change counts where a neighbour along the row changed too: noise is per pixel, a moving edge is not
        for x in range(W):
            moving[x] = changed[x] & ((x > 0 and changed[x - 1]) | (x + 1 < W and changed[x + 1]))
        changed[:] = moving
        for o in range(1, spread + 1):
            for x in range(W - o):
                moving[x] |= changed[x + o]
            for x in range(o, W):
                moving[x] |= changed[x - o]
        for x in range(W):
            if moving[x] == 0:
                continue
            n_moving += 1
            for c in range(C):
                out[y, x, c] = inverse[c, inverse_bin(h[x, c] + l[x, c] - n[x, c], grid)]
    return n_moving


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def inverse_bin(value: np.float32, grid: np.ndarray) -> int:
    """The bin of the inverse table (motion.inverse_table) nearest to a linear value: grid = (first bin's value,
    bins per linear unit, number of bins), float32; values outside are clamped to the first or last bin."""
    b = int((value - grid[0]) * grid[1] + np.float32(0.5))
    return min(max(b, 0), int(grid[2]) - 1)
