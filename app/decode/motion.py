"""Motion-tolerant two-shot decoding: the newest frame decodes alone where the scene moved.

A two-shot pair (frame 2 the per-channel inverse of frame 1) decodes from the sign of frame2 - frame1. When the
object moves between the two frames, a stripe moves by more than its own width and that sign is wrong. But each
two-shot frame alone is already a one-shot code with the same windows: its channels' levels are the code, and the
other frame only their inverse. So where the newest frame differs from the previous frame of the same pattern (the
frame before the pair), the older frame of the pair is replaced by the newest frame's inverse about its local
envelope, or, where both frames of the pair keep their local mean level, about the mean of both
(`app/decode/fast/motion.py`), and the unchanged two-shot decoder decodes the newest frame's geometry there. Where
nothing changed the pair is decoded as it is, bit for bit. Without a previous frame (the first pair of a stream, a
lone pair) there is no evidence of motion and the pair is decoded as it is.

`repair_reference` states the computation in plain numpy; `fast.repair_older` is the compiled form the decoders use.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.decode.colour import CHANNEL_INDEX
from app.decode.fast.differences import pair_tables
from app.decode.fast.motion import MEAN_SCALE, quantised_table, quiet_distances, repair_older
from app.errors import InputError

MOTION_MODES = ("auto", "off")


@dataclass(frozen=True)
class MotionParams:
    """When a pixel counts as moving, and how the newest frame is thresholded there."""

    # The newest frame's envelope (its largest and smallest linear value per channel along the row): over the
    # narrow window where that holds both levels of the channel (its contrast at least narrow_share of the wide
    # window's), else over the wide one. Half-widths in px; a stripe is ~2 px, a channel keeps its level for up
    # to a few stripes, and a narrow window reaches across fewer albedo and depth edges.
    narrow_radius: int = 4
    wide_radius: int = 9
    narrow_share: float = 0.6
    spread: int = 5  # a moving pixel marks this many neighbours either side along the row (stripe edges near it)
    change_rel: float = 0.6  # a change must exceed this share of the local contrast (hi - lo) ...
    change_noise: float = 8.0  # ... this multiple of the two frames' noise slopes (linear per raw 8-bit step) ...
    change_floor: float = 5.0  # ... and this many linear 8-bit units (dark surfaces' noise, compressed by gamma)
    # Where the newest and the older frame's local means along the row (half-width mean_radius, and over each half
    # of that window) agree within mean_share of their sum plus mean_floor linear units in every watched channel,
    # the pair's sum of both levels comes from those means instead of the newest frame's envelope.
    mean_radius: int = 12
    mean_share: float = 0.35
    mean_floor: float = 2.0

    def limits(self) -> np.ndarray:
        change = [self.change_rel, self.change_noise, self.change_floor]
        return np.array([*change, self.narrow_share, self.mean_share, self.mean_floor], np.float32)

    def radii(self) -> np.ndarray:
        return np.array([self.narrow_radius, self.wide_radius, self.mean_radius], np.int64)


def check_motion_mode(value: object, where: str) -> str:
    """'auto' or 'off' (YAML's bare off reads as False), else an InputError naming where."""
    if value is False:
        return "off"
    if value not in MOTION_MODES:
        raise InputError(f"{where}: motion must be one of {', '.join(MOTION_MODES)}, found {value!r}")
    return str(value)


def watched_channels(channels: str) -> np.ndarray:
    """The camera channels whose change marks motion: those of the pattern's channels."""
    return np.array(sorted(CHANNEL_INDEX[c] for c in channels.upper()), np.int64)


INVERSE_BINS = 4096  # the inverse table's bins over the linear range: 0.06 linear 8-bit units each


def inverse_table(lin: np.ndarray, bins: int = INVERSE_BINS) -> tuple[np.ndarray, np.ndarray]:
    """Linear value -> raw level: (inverse (3, bins) of each bin's nearest raw level per channel, the lower on a
    tie; grid float32 (first bin's value, bins per linear unit, bins)), over the range of all channels."""
    first, last = float(lin.min()), float(lin.max())
    scale = (bins - 1) / max(last - first, 1e-12)
    centres = (first + np.arange(bins) / scale).astype(np.float32)
    inverse = np.empty((lin.shape[0], bins), np.int32)
    for c in range(lin.shape[0]):
        i = np.searchsorted(lin[c], centres, side="left").clip(0, lin.shape[1] - 1)
        below = np.maximum(i - 1, 0)
        take_below = (i > 0) & (centres - lin[c, below] <= lin[c, i] - centres)
        inverse[c] = np.where(take_below, below, i)
    return inverse, np.array([first, scale, bins], np.float32)


def quantised(values: np.ndarray) -> np.ndarray:
    """Linear values (float32) in int32 steps of 1 / MEAN_SCALE, rounded, negative ones to 0 (fast.motion.quantise):
    the local sums' terms."""
    return np.maximum(values * np.float32(MEAN_SCALE) + np.float32(0.5), np.float32(0.0)).astype(np.int32)


def window_constants(W: int, radius: int, floor: float) -> np.ndarray:
    """fast.motion._window_constants in numpy: (4, W) float32, per pixel of a row the floor in quantised sums'
    units over the window, its left half and its right half (clipped at the row's ends), and the window's
    reciprocal count in linear units per sum."""
    x = np.arange(W)
    first, last = np.maximum(x - radius, 0), np.minimum(x + radius + 1, W)
    scale = np.float32(MEAN_SCALE)
    counts = [last - first, x + 1 - first, last - x]
    out = [np.float32(floor) * (scale * c.astype(np.float32)) for c in counts]
    return np.stack([*out, np.float32(1.0) / (scale * counts[0].astype(np.float32))]).astype(np.float32)


class MotionRepair:
    """The repair of a pair's older frame (fast.repair_older) with its tables built once (per decoder and frame
    depth)."""

    def __init__(self, luts: tuple[np.ndarray, np.ndarray], channels: str, params: MotionParams) -> None:
        lin, dlin = luts
        self.levels = lin.shape[1]
        self.watched = watched_channels(channels)
        self.limits, self.radii, self.spread = params.limits(), params.radii(), int(params.spread)
        quiet = quiet_distances(lin, dlin, self.limits)
        pairs = pair_tables(lin, dlin)  # (empty unless 8-bit)
        self.tables = (lin, dlin, pairs, *inverse_table(lin), quantised_table(lin), quiet)

    def __call__(self, newest: np.ndarray, older: np.ndarray, previous: np.ndarray) -> tuple[np.ndarray, int]:
        """(the older frame repaired where the scene moved, the number of moving pixels); frames (H, W, 3) of one
        dtype, previous the frame before the older one (it saw the newest frame's pattern). A previous frame of
        another size or dtype is an InputError."""
        if previous.shape != newest.shape or previous.dtype != newest.dtype:
            raise InputError(
                f"previous frame for motion is {previous.shape} {previous.dtype}, "
                f"the pair {newest.shape} {newest.dtype}"
            )
        frames = tuple(np.ascontiguousarray(f) for f in (newest, older, previous))
        out = np.empty_like(frames[1])
        n = repair_older(frames, self.tables, self.watched, self.limits, self.radii, self.spread, out)
        return out, int(n)


def repair_reference(
    newest: np.ndarray,
    older: np.ndarray,
    previous: np.ndarray,
    luts: tuple[np.ndarray, np.ndarray],
    channels: str,
    params: MotionParams,
) -> tuple[np.ndarray, int]:
    """MotionRepair(luts, channels, params)(newest, older, previous) in plain numpy: the specification of
    `fast.repair_older`."""
    lin, dlin = luts
    ch = np.arange(3)
    ln, lp = lin[ch, newest], lin[ch, previous]  # (H, W, 3) linear values
    W = newest.shape[1]

    def envelope(r: int) -> tuple[np.ndarray, np.ndarray]:
        hi, lo = ln.copy(), ln.copy()
        for o in range(1, r + 1):  # window extremes along the row, clipped at its ends
            hi[:, : W - o] = np.maximum(hi[:, : W - o], ln[:, o:])
            hi[:, o:] = np.maximum(hi[:, o:], ln[:, : W - o])
            lo[:, : W - o] = np.minimum(lo[:, : W - o], ln[:, o:])
            lo[:, o:] = np.minimum(lo[:, o:], ln[:, : W - o])
        return hi, lo

    hi, lo = envelope(params.narrow_radius)
    wide_hi, wide_lo = envelope(params.wide_radius)
    narrow = hi - lo >= np.float32(params.narrow_share) * (wide_hi - wide_lo)
    hi, lo = np.where(narrow, hi, wide_hi), np.where(narrow, lo, wide_lo)
    slopes = dlin[ch, newest] + dlin[ch, previous]
    limit = np.maximum(
        np.maximum(np.float32(params.change_rel) * (hi - lo), np.float32(params.change_noise) * slopes),
        np.float32(params.change_floor),
    )
    w = watched_channels(channels)
    changed = (np.abs(ln - lp) > limit)[..., w].any(axis=2)
    neighbour = np.zeros_like(changed)  # a change counts where a neighbour along the row changed too
    neighbour[:, 1:] |= changed[:, :-1]
    neighbour[:, :-1] |= changed[:, 1:]
    changed &= neighbour
    moving = changed.copy()
    for o in range(1, params.spread + 1):
        moving[:, : W - o] |= changed[:, o:]
        moving[:, o:] |= changed[:, : W - o]
    qn, qo = quantised(ln), quantised(lin[ch, older])

    def window_sums(v: np.ndarray, lo_off: int, hi_off: int) -> np.ndarray:  # windows clipped at the row's ends
        sums = np.zeros((v.shape[0], W + 1, 3), np.int64)
        sums[:, 1:] = np.cumsum(v, axis=1)
        x = np.arange(W)
        first, last = np.maximum(x + lo_off, 0), np.minimum(x + hi_off + 1, W)
        return sums[:, last].astype(np.float32) - sums[:, first].astype(np.float32)  # (exact: integers below 2^24)

    r = params.mean_radius
    constants = window_constants(W, r, params.mean_floor)
    agree = np.ones(newest.shape[:2], bool)
    for k, lo_off, hi_off in ((0, -r, r), (1, -r, 0), (2, 0, r)):  # the window, then its halves
        sn, so = window_sums(qn, lo_off, hi_off), window_sums(qo, lo_off, hi_off)
        limit = np.float32(params.mean_share) * (sn + so) + constants[k][None, :, None]
        agree &= (np.abs(sn - so) <= limit)[..., w].all(axis=2)
    sn, so = window_sums(qn, -r, r), window_sums(qo, -r, r)
    both = np.where(agree[..., None], (sn + so) * constants[3][None, :, None], hi + lo)  # the sum of both levels
    inverse, grid = inverse_table(lin)
    target = both - ln  # the newest frame's inverse about that sum, in linear units
    bins = np.clip(((target - grid[0]) * grid[1] + np.float32(0.5)).astype(np.int64), 0, int(grid[2]) - 1)
    out = older.copy()
    for c in range(3):
        out[..., c][moving] = inverse[c, bins[..., c][moving]]
    return out, int(moving.sum())
