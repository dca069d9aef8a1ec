"""Stripe identification by windows of k stripes, shared by the one-shot and two-shot decoders."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.decode import fast
from app.decode.fast.lacking_edges import NO_LACKING_EDGES
from app.decode.stripemap import StripeMap
from core.patterns import check_window_keys, window_table

EMPTY_RANGE = np.zeros((1, 1), np.float32)


def window_lookup(sequence: Sequence[int], k: int, alphabet: int) -> np.ndarray:
    """Array over window keys sum(code[t] * alphabet**t) -> start index in the sequence, or -1.
    int32, the narrowest values gather instructions read (4**7 keys take 64 KB; a row's ~300 windows touch a
    small part of it)."""
    check_window_keys(alphabet, k, "scheme.k")
    table = np.full(alphabet**k, -1, np.int32)
    powers = alphabet ** np.arange(k)
    for window, start in window_table(sequence, k).items():
        table[int(np.dot(window, powers))] = start
    return table


@dataclass(frozen=True)
class WindowSpec:
    """Everything `fast.label_rows` needs to know about a stripe sequence."""

    table: np.ndarray  # (A**k,) int32
    link_ok: np.ndarray  # (A, A) bool: codes allowed to be neighbouring stripes
    weights: np.ndarray  # (A, A, C) float32: edge signal a->b = sum_c w * feat[..., c], > 0 on the a side
    k: int
    period: int
    stripe_width: int
    proj_width: int

    @property
    def n_copies(self) -> int:
        return -(-self.proj_width // (self.period * self.stripe_width))

    def stripe_code(self) -> fast.StripeCode:
        """The tables the compiled decoders read."""
        return fast.StripeCode(self.table, self.link_ok, self.weights)


@dataclass(frozen=True)
class LabelParams:
    gap_max: int = 2  # camera pixels without a code allowed between neighbouring stripes
    edges: bool = True  # sub-pixel nodes at stripe edges (zero crossings) instead of stripe centres
    vertical_tol: float = 2.0  # projector px: a value agrees with the rows above/below within this
    min_support: float = 0.3  # agreeing vertical neighbours per pixel a chain needs (0..2)
    min_frac: float = 0.7  # share of a chain's pixels inside the depth range for its copy to be chosen
    smooth: int = 2  # sub-pixel nodes: local line fit over +-smooth neighbouring nodes (0 = raw)
    events: bool = False  # two-shot: stripes from per-channel zero crossings instead of pixel runs
    # two-shot from a raw mosaic: the edges of the channel it samples in every other column placed from the G
    # edges where that channel aliases the stripes (fast/lacking_edges.py)
    mosaic_edges: bool = True


def label_settings(
    spec: WindowSpec, params: LabelParams, use_range: bool, lacking_bit: int = NO_LACKING_EDGES
) -> fast.LabelSettings:
    """The labelling parameters the compiled decoders read; lacking_bit: the code bit of the channel a raw mosaic
    samples in every other column, whose edges come from the G edges (fast/lacking_edges.py)."""
    return fast.LabelSettings(
        int(spec.k),
        int(spec.period),
        int(spec.stripe_width),
        int(spec.n_copies),
        int(spec.proj_width),
        int(params.gap_max),
        float(params.min_frac),
        int(params.smooth),
        float(params.vertical_tol),
        float(params.min_support),
        bool(params.edges),
        bool(use_range),
        int(lacking_bit) if params.mosaic_edges else NO_LACKING_EDGES,
    )


def label(
    code: np.ndarray,
    feat: np.ndarray,
    spec: WindowSpec,
    params: LabelParams,
    column_range: tuple[np.ndarray, np.ndarray] | None,
    thresholds: np.ndarray | None = None,
) -> StripeMap:
    """Identify stripes row by row; thresholds (H, W, C) of |feat| for a sign feed the event mode."""
    H, W = code.shape
    col = np.full((H, W), np.nan, np.float32)
    chain = np.full((H, W), -1, np.int32)
    use_range = column_range is not None
    lo, hi = column_range if use_range else (EMPTY_RANGE, EMPTY_RANGE)
    n = fast.label_rows(
        code,
        feat,
        thresholds if thresholds is not None else np.zeros((1, 1, 1), np.float32),
        params.events,
        spec.stripe_code(),
        label_settings(spec, params, use_range),
        lo,
        hi,
        col,
        chain,
    )
    dropped = 0
    if params.vertical_tol > 0:
        dropped = fast.vertical_check(col, chain, n, params.vertical_tol, params.min_support)
    conf = np.where(np.isfinite(col), np.float32(1.0), np.float32(0.0))
    return StripeMap(
        col,
        conf,
        stripe_width=spec.stripe_width,
        period=spec.period,
        copy_known=use_range or spec.n_copies == 1,
        chain=chain,
        info={"chains": int(n), "chains_dropped": int(dropped)},
    )
