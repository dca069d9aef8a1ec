"""Plain numpy/Python reference of the colour decoders: the specification the compiled path is tested against.

Written for reading, not speed. It builds every table itself from the pattern's parameters and the rig's
calibration inputs (camera gamma or response, colour mixing, depth-range column bounds) and takes only the
decoders' *settings* (TwoShotParams, OneShotParams, LabelParams): a set-up bug in the fast path
(`TwoShotDecoder` -> `app/decode/fast/`) is then not shared by the reference. The stages, in the
paper's order (Je, Lee & Park 2004, sections 3-4):

1. per-pixel classification: linearise, unmix, per-channel sign (two-shot) or colour (one-shot);
2. stripes of a row and the links between neighbours: pixel runs of one code, or intervals between the
   channels' zero crossings (events), with sub-pixel edges;
3. window lookup: k linked stripes -> position in the sequence;
4. confirmed labels: a window counts when an adjacent window continues it;
5. chains (consecutively labelled, linked stripes) and the vote for the sequence copy from the depth range;
6. column write: interpolation between the chain's nodes (stripe edges), kept inside the chain and the
   pixel's depth-range interval;
7. vertical check: a chain survives only where the rows above and below agree with it;
8. for the "both" segmentation: the runs' map merged into the events' map.

Entry points: `decode_two_shot(pattern_params, frame1, frame2, ...)`, `decode_one_shot(pattern_params, image,
...)`; `decode(dec, f1, f2)` is a thin adapter reading a TwoShotDecoder's settings (never its tables).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from app.decode.stripemap import StripeMap
from app.decode.twoshot import TwoShotParams
from app.decode.windows import LabelParams

CAMERA_CHANNEL = {"R": 0, "G": 1, "B": 2}  # camera and projector primaries, in frame channel order
MERGE_TOL = 0.5  # "both": projector px beyond which the events' and the runs' values of a pixel clash
END_EXT = 0.5  # stripes: a chain's pixels reach this far beyond its outer nodes (the end stripes' own pixels)


# ---------------------------------------------------------------------------------------------- tables


def linearisation(levels: int, gamma: float = 1.0, response: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lin, slope), float32 (3, levels): raw camera value -> linear light in 8-bit units (0..255), and the
    curve's slope per raw 8-bit step.

    A noise floor given in raw 8-bit DN becomes a floor in linear light through the slope, at every level
    (a gamma-encoding camera compresses dark values and their noise alike). `response` (levels,) or
    (3, levels), the measured raw -> linear curve in 0..1, wins over gamma; one measured for another bit
    depth does not apply (gamma is used). The slope is the central difference of neighbouring levels
    (one-sided at both ends), never negative.
    """
    r = None if response is None else np.asarray(response, np.float64)
    if r is not None and r.shape[-1] == levels and r.size in (levels, 3 * levels):
        curve = 255.0 * np.broadcast_to(r.reshape(-1, levels), (3, levels))
    else:
        raw = np.arange(levels, dtype=np.float64) / (levels - 1)
        curve = np.broadcast_to(255.0 * raw**gamma, (3, levels))
    per_level = np.empty_like(curve)
    per_level[:, 1:-1] = (curve[:, 2:] - curve[:, :-2]) / 2
    per_level[:, 0] = curve[:, 1] - curve[:, 0]
    per_level[:, -1] = curve[:, -1] - curve[:, -2]
    slope = per_level * ((levels - 1) / 255.0)  # per raw level -> per 8-bit step
    return curve.astype(np.float32), np.maximum(slope, 0.0).astype(np.float32)


def unmixing(mixing: np.ndarray | None) -> np.ndarray:
    """3x3 float32: linear camera RGB -> projector primaries. mixing[i, j] is camera channel i's response to
    primary j; each primary's column is scaled so its own channel reads 1 before inverting, so an unmixed
    value stays in camera units of that channel (thresholds keep their meaning)."""
    if mixing is None:
        return np.eye(3, dtype=np.float32)
    M = np.asarray(mixing, np.float64).reshape(3, 3)
    own = np.diag(M).copy()
    own[own == 0] = 1.0
    return np.linalg.inv(M / own[None, :]).astype(np.float32)


def unmixing_rows(mixing: np.ndarray | None, channels: str) -> np.ndarray:
    """The unmixing rows of the pattern's channels, in code-bit order: (m, 3) float32."""
    return unmixing(mixing)[[CAMERA_CHANNEL[c] for c in channels.upper()]].astype(np.float32)


def window_positions_of(sequence, k: int) -> dict[tuple[int, ...], int]:
    """Every cyclic window of k consecutive codes of the sequence -> the index of its first stripe. Each
    window occurs once (the sequence's defining property; a repeat would make the lookup ambiguous)."""
    seq = [int(v) for v in sequence]
    n = len(seq)
    table = {tuple(seq[(i + t) % n] for t in range(k)): i for i in range(n)}
    if len(table) != n:
        raise ValueError("sequence has repeated windows")
    return table


@dataclass(frozen=True)
class Pattern:
    """What labelling needs to know about a stripe pattern, derived from its parameters."""

    sequence: tuple[int, ...]
    k: int
    stripe_width: int
    proj_width: int
    windows: dict  # window (k codes) -> sequence position
    link: np.ndarray  # (A, A) bool: codes that may be neighbouring stripes
    edge_weights: np.ndarray  # (A, A, C): edge signal a -> b = weights . feature, > 0 on the a side

    @property
    def period(self) -> int:
        return len(self.sequence)

    @property
    def n_copies(self) -> int:
        """Copies of the sequence across the projector (the last one may be partial)."""
        return -(-self.proj_width // (self.period * self.stripe_width))


def two_shot_pattern(pattern_params: dict, proj_width: int) -> Pattern:
    """Two-shot codes are m-bit patterns (bit c = channel c at max in frame 1). Neighbouring stripes differ
    in exactly one bit (paper eq. 7), and that channel's difference changes sign at their edge: the edge signal
    is that difference, signed to be > 0 on the first stripe's side (d < 0 where the bit is 1)."""
    m = len(str(pattern_params["channels"]))
    A = 1 << m
    link = np.zeros((A, A), bool)
    weights = np.zeros((A, A, m), np.float32)
    for a in range(A):
        for b in range(A):
            flipped = [c for c in range(m) if (a ^ b) >> c & 1]
            if len(flipped) == 1:
                c = flipped[0]
                link[a, b] = True
                weights[a, b, c] = -1.0 if a >> c & 1 else 1.0  # bit 1: d < 0 on the a side
    seq = tuple(int(v) for v in pattern_params["sequence"])
    k = int(pattern_params["k"])
    sw = int(pattern_params["stripe_width"])
    return Pattern(seq, k, sw, proj_width, window_positions_of(seq, k), link, weights)


def one_shot_pattern(pattern_params: dict, proj_width: int) -> tuple[Pattern, np.ndarray]:
    """One-shot codes index the pattern's colours; neighbours differ in colour (paper eq. 1), and their edge
    signal is the first colour's level minus the second's. Also returns each colour's primary (N,)."""
    colours = str(pattern_params["colors"]).upper()
    rows = np.array([CAMERA_CHANNEL[c] for c in colours], np.int64)
    N = len(colours)
    link = ~np.eye(N, dtype=bool)
    weights = np.zeros((N, N, 3), np.float32)
    for a in range(N):
        for b in range(N):
            if a != b:
                weights[a, b, rows[a]] = 1.0
                weights[a, b, rows[b]] = -1.0
    seq = tuple(int(v) for v in pattern_params["sequence"])
    k = int(pattern_params["k"])
    sw = int(pattern_params["stripe_width"])
    return Pattern(seq, k, sw, proj_width, window_positions_of(seq, k), link, weights), rows


def columns_run_backwards(column_range: tuple[np.ndarray, np.ndarray] | None) -> bool:
    """A mirrored rig (projector columns falling as camera x grows, median over the image): windows would be
    read backwards, so the image is decoded mirrored and the result mirrored back."""
    if column_range is None or column_range[0].ndim != 2 or column_range[0].shape[1] < 2:
        return False
    middle = 0.5 * (column_range[0] + column_range[1])
    step = (middle[:, 1:] - middle[:, :-1]).ravel()
    step = step[np.isfinite(step)]
    return step.size > 0 and float(np.median(step)) < 0


def _proj_width(pattern_params: dict, proj_width: int | None) -> int:
    return int(proj_width if proj_width is not None else pattern_params["size"][0])


def _as_range(column_range) -> tuple[np.ndarray, np.ndarray] | None:
    """The depth range's per-pixel projector column interval [lo, hi] (NaN: no column possible), float32."""
    if column_range is None:
        return None
    return tuple(np.asarray(r, np.float32) for r in column_range)


def _flip(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a[:, ::-1])


def _mirror_back(sm: StripeMap) -> StripeMap:
    """The stripe map of a mirrored image on the original pixels (its projector columns stay as they are)."""
    sm.column = _flip(sm.column)
    sm.confidence = np.isfinite(sm.column).astype(np.float32)
    sm.chain = _flip(sm.chain)
    sm.info = {**sm.info, "mirrored": True}
    return sm


# ------------------------------------------------------------------------------------- entry points


def decode_two_shot(
    pattern_params: dict,
    frame1: np.ndarray,
    frame2: np.ndarray,
    *,
    mixing: np.ndarray | None = None,
    gamma: float = 1.0,
    response: np.ndarray | None = None,
    column_range: tuple[np.ndarray, np.ndarray] | None = None,
    params: TwoShotParams | None = None,
    proj_width: int | None = None,
) -> StripeMap:
    """Projector columns (NaN = none) of a two-shot pair: frame1 saw pattern 0, frame2 pattern 1.

    pattern_params: the export's parameters (sequence, k, stripe_width, channels; `size` gives the projector
    width unless proj_width does). mixing: calibration color_mixing; gamma / response: the camera's;
    column_range: the triangulator's per-pixel (lo, hi) projector columns of the depth range."""
    p = params or TwoShotParams()
    pattern = two_shot_pattern(pattern_params, _proj_width(pattern_params, proj_width))
    rng = _as_range(column_range)
    if columns_run_backwards(rng):
        rng = None if rng is None else (_flip(rng[0]), _flip(rng[1]))
        sm = _decode_two_shot(pattern, pattern_params, _flip(frame1), _flip(frame2), mixing, gamma, response, rng, p)
        return _mirror_back(sm)
    return _decode_two_shot(pattern, pattern_params, frame1, frame2, mixing, gamma, response, rng, p)


def _decode_two_shot(pattern, pattern_params, f1, f2, mixing, gamma, response, rng, p) -> StripeMap:
    levels = 65536 if f1.dtype == np.uint16 else 256
    lin, slope = linearisation(levels, gamma, response)
    U = unmixing_rows(mixing, str(pattern_params["channels"]))
    code, feat, thr = classify_two_shot(f1, f2, lin, slope, U, p)
    if p.segmentation == "both":
        a = label_rows(code, feat, thr, pattern, p.label, rng, events=True)
        b = label_rows(code, feat, thr, pattern, p.label, rng, events=False)
        return merge(a, b)
    if p.segmentation not in ("events", "runs"):
        raise ValueError(f"segmentation {p.segmentation!r} is not one of events, runs, both")
    return label_rows(code, feat, thr, pattern, p.label, rng, events=p.segmentation == "events")


def decode(dec, f1: np.ndarray, f2: np.ndarray, mixing: np.ndarray | None = None) -> StripeMap:
    """decode_two_shot with a TwoShotDecoder's settings (its pattern, camera and params, never its tables); its
    column range as it was given (un-mirrored). The decoder keeps no mixing matrix: pass the one it was given."""
    rng = dec.column_range
    if rng is not None and dec.mirrored:
        rng = (_flip(rng[0]), _flip(rng[1]))
    spec = dec.spec
    params = {"sequence": dec.sequence, "k": spec.k, "stripe_width": spec.stripe_width, "channels": dec.channels}
    return decode_two_shot(
        params,
        f1,
        f2,
        mixing=mixing,
        gamma=dec.camera_gamma,
        response=dec.camera_response,
        column_range=rng,
        params=dec.params,
        proj_width=spec.proj_width,
    )


def decode_one_shot(
    pattern_params: dict,
    image: np.ndarray,
    *,
    mixing: np.ndarray | None = None,
    gamma: float = 1.0,
    column_range: tuple[np.ndarray, np.ndarray] | None = None,
    params=None,
    proj_width: int | None = None,
) -> StripeMap:
    """Projector columns (NaN = none) of a one-shot frame (settings: OneShotParams)."""
    from app.decode.oneshot import OneShotParams

    p = params or OneShotParams()
    pattern, _ = one_shot_pattern(pattern_params, _proj_width(pattern_params, proj_width))
    rng = _as_range(column_range)
    mirrored = columns_run_backwards(rng)
    if mirrored:
        image = _flip(image)
        rng = None if rng is None else (_flip(rng[0]), _flip(rng[1]))
    code, feat = classify_one_shot(pattern_params, image, mixing=mixing, gamma=gamma, params=p)
    sm = label_rows(code, feat, None, pattern, p.label, rng, events=False)
    return _mirror_back(sm) if mirrored else sm


# ------------------------------------------------------------------------- 1. per-pixel classification


def _local_amplitude(values: np.ndarray, block: int, op, pad: float) -> np.ndarray:
    """Per pixel and channel, op (max or min) of `values` (H, W, C) over the pixel's block of `block` pixels
    along the row and the blocks either side: a few stripes' worth, so one stripe's level never sets it."""
    H, W, C = values.shape
    nb = -(-W // block)
    padded = np.full((H, nb * block, C), pad, np.float32)
    padded[:, :W] = values
    blocks = op.reduce(padded.reshape(H, nb, block, C), axis=2)
    edge = np.full_like(blocks[:, :1], pad)
    around = op(blocks, op(np.concatenate([edge, blocks[:, :-1]], 1), np.concatenate([blocks[:, 1:], edge], 1)))
    return around[:, np.arange(W) // block]


def classify_two_shot(
    f1: np.ndarray, f2: np.ndarray, lin: np.ndarray, slope: np.ndarray, U: np.ndarray, p: TwoShotParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(code, feat, thr): per pixel the code (bit c set where channel c was at max in frame 1, i.e. its
    unmixed linear difference frame2 - frame1 is negative; -1 when a channel has no sure sign), the unmixed
    differences (H, W, m) and the events' sign thresholds (H, W, m).

    Ambient light and surface colour scale |d| but never flip its sign. A sign is sure when |d| is above the
    noise floor (t_abs raw 8-bit DN in each frame, through the response slope and the unmixing) and above
    t_rel of the channel's local amplitude (so a stripe edge, where d crosses zero, has no code while a
    weakly reflecting channel keeps its signs)."""
    ch = np.arange(3)
    d = lin[ch, f2] - lin[ch, f1]  # (H, W, 3) linear camera differences
    noise_slope = slope[ch, f2] + slope[ch, f1]
    feat = np.einsum("cj,hwj->hwc", U, d).astype(np.float32)
    noise = (p.t_abs * 0.5 * np.einsum("cj,hwj->hwc", np.abs(U), noise_slope)).astype(np.float32)
    amp = _local_amplitude(np.abs(feat), p.block, np.maximum, 0.0)
    sure = np.abs(feat) >= np.maximum(noise, p.t_rel * amp)
    bits = ((feat < 0) << np.arange(feat.shape[2])).sum(axis=2)
    code = np.where(sure.all(axis=2), bits, -1)
    thr = np.maximum(noise, p.t_rel_edges * amp)
    return code, feat, thr


def classify_one_shot(
    pattern_params, image: np.ndarray, *, mixing: np.ndarray | None = None, gamma: float = 1.0, params=None
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel colour index into the pattern's colours (-1 = none) and the normalised levels (H, W, 3).

    Each unmixed primary is normalised by its local min and max along the row (discounting ambient light and
    surface colour per channel), or with use_hue by the pixel's brightness (the paper's chromaticity); the
    best colour must beat the second by t_margin."""
    from app.decode.oneshot import OneShotParams

    p = params or OneShotParams()
    _, rows = one_shot_pattern(pattern_params, 1)
    lin, _ = linearisation(65536 if image.dtype == np.uint16 else 256, gamma)
    linear = np.stack([lin[c][image[..., c]] for c in range(3)], axis=-1).astype(np.float32)
    u = np.einsum("cj,hwj->hwc", unmixing(mixing), linear).astype(np.float32)
    if p.use_hue:
        v = np.maximum(u, 0)
        total = v.sum(axis=2, keepdims=True)
        feat = np.where(total >= p.t_abs, v / np.where(total > 0, total, 1), 0).astype(np.float32)
    else:
        hi = _local_amplitude(u, p.block, np.maximum, -np.inf)
        lo = _local_amplitude(u, p.block, np.minimum, np.inf)
        span = hi - lo
        feat = np.where(span >= p.t_abs, (u - lo) / np.where(span > 0, span, 1), 0).astype(np.float32)
    levels = feat[..., rows]  # (H, W, N) in the pattern's colour order
    order = np.argsort(-levels, axis=2, kind="stable")
    v1 = np.take_along_axis(levels, order[..., :1], 2)[..., 0]
    v2 = np.take_along_axis(levels, order[..., 1:2], 2)[..., 0] if levels.shape[2] > 1 else np.full_like(v1, -1)
    code = np.where((v1 - v2 >= p.t_margin) & (v1 > 0), order[..., 0], -1)
    return code, feat


# ------------------------------------------------------------------ 2. stripes of a row and their links


@dataclass
class Stripe:
    left: float  # first and last whole pixel: ceil(left) .. floor(right)
    right: float
    code: int
    linked: bool = False  # may be the neighbour of the next stripe (small gap, allowed transition)
    edge: float = 0.0  # sub-pixel edge to the next stripe (where linked)


def _channel_events(d: np.ndarray, thr: np.ndarray, gap_max: int) -> list[tuple[float, int, int]]:
    """A channel's (position, kind, sign) along a row: kind 0 = its sign becomes known, 1 = its sign changes
    (at the raw zero crossing between the two signed pixels), 2 = unknown (a gap over gap_max pixels, or the
    row's end)."""
    s = np.where(d >= thr, 1, np.where(d <= -thr, -1, 0))
    xs = np.flatnonzero(s)
    out: list[tuple[float, int, int]] = []
    for i, x in enumerate(xs):
        if i == 0:
            out.append((x - 0.5, 0, int(s[x])))
            continue
        px = xs[i - 1]
        if x - px - 1 > gap_max:
            out += [(px + 0.5, 2, 0), (x - 0.5, 0, int(s[x]))]
        elif s[x] != s[px]:
            seg = d[px : x + 1]
            cross = np.flatnonzero((seg[:-1] > 0) != (seg[1:] > 0))
            if len(cross):  # the first raw sign change, interpolated between its two pixels
                j = px + cross[0]
                out.append((j + d[j] / (d[j] - d[j + 1]), 1, int(s[x])))
            else:
                out.append((px + d[px] / (d[px] - d[x]) * (x - px), 1, int(s[x])))
    if len(xs):
        out.append((xs[-1] + 0.5, 2, 0))
    return out


def event_stripes(feat_row: np.ndarray, thr_row: np.ndarray, gap_max: int) -> list[Stripe]:
    """Stripes as the intervals between consecutive events of any channel while every channel has a sign
    (so a stripe narrower than a pixel is still seen when the crossings around it are). Two stripes are
    linked when the event between them is a sign change: its position is their edge."""
    m = feat_row.shape[1]
    events = []
    for c in range(m):
        events += [(x, c, kind, s) for x, kind, s in _channel_events(feat_row[:, c], thr_row[:, c], gap_max)]
    events.sort(key=lambda e: (e[0], e[1]))  # ties: the lower channel first
    sign = [0] * m
    out: list[Stripe] = []
    active = False
    for x, c, kind, s in events:
        if active:
            out[-1].right = x
        was = active
        sign[c] = s
        active = all(sign)
        if active:
            if out and was and kind == 1:
                out[-1].linked, out[-1].edge = True, x
            out.append(Stripe(x, x, sum(1 << i for i in range(m) if sign[i] < 0)))
    return out


def run_stripes(code_row: np.ndarray, feat_row: np.ndarray, pattern: Pattern, gap_max: int) -> list[Stripe]:
    """Stripes as maximal pixel runs of one code. Neighbouring runs are linked when at most gap_max pixels
    lie between them and their codes may be neighbours; their edge is the falling zero crossing of the edge
    signal between their facing pixels (from the run's second-last pixel to the next's second) closest to
    the middle of the gap, else that middle."""
    out: list[Stripe] = []
    x, W = 0, len(code_row)
    while x < W:
        if code_row[x] < 0:
            x += 1
            continue
        s = x
        while x + 1 < W and code_row[x + 1] == code_row[s]:
            x += 1
        out.append(Stripe(s, x, int(code_row[s])))
        x += 1
    for a, b in pairwise(out):
        rs, re, nrs, nre = int(a.left), int(a.right), int(b.left), int(b.right)
        a.linked = bool(nrs - re - 1 <= gap_max and pattern.link[a.code, b.code])
        if not a.linked:
            continue
        xa = re - 1 if re - 1 >= rs else re
        xb = nrs + 1 if nrs + 1 <= nre else nrs
        mid = 0.5 * (re + nrs)
        sig = feat_row @ pattern.edge_weights[a.code, b.code]
        best, bestd = mid, 1e9
        for xx in range(xa, xb):
            s0, s1 = sig[xx], sig[xx + 1]
            if s0 > 0 and s1 <= 0:
                xz = xx + s0 / (s0 - s1)
                if abs(xz - mid) < bestd:
                    best, bestd = xz, abs(xz - mid)
        a.edge = best
    return out


# ------------------------------------------------------------- 3. windows, 4. confirmed labels, 5. chains


def window_positions(stripes: list[Stripe], pattern: Pattern) -> list[int]:
    """pos[j]: the sequence position of the window of stripes j..j+k-1, -1 unless they are k stripes linked
    one to the next whose codes form a window of the sequence."""
    k, n = pattern.k, len(stripes)
    pos = [-1] * n
    for j in range(n - k + 1):
        if all(stripes[j + t].linked for t in range(k - 1)):
            pos[j] = pattern.windows.get(tuple(s.code for s in stripes[j : j + k]), -1)
    return pos


def confirmed_labels(pos: list[int], k: int, period: int) -> list[int]:
    """Each stripe's label (sequence index) from the confirmed windows over it: a window is confirmed when
    the window before or after it continues it (position + 1). -1 none, -2 where windows disagree. (In a
    two-shot sequence every walk of one-bit changes is a window, so one window alone says nothing; the one
    next to it continues it only if the next code is the sequence's, and the vertical check does the rest.)"""
    n = len(pos)
    lab = [-1] * n
    for j, p in enumerate(pos):
        if p < 0:
            continue
        after = j + 1 < n and pos[j + 1] == (p + 1) % period
        before = j > 0 and pos[j - 1] >= 0 and p == (pos[j - 1] + 1) % period
        if not (after or before):
            continue
        for t in range(k):
            lv = (p + t) % period
            lab[j + t] = lv if lab[j + t] in (-1, lv) else -2
    return lab


def chains(stripes: list[Stripe], lab: list[int], k: int, period: int) -> list[tuple[int, int]]:
    """(first, last) stripe of each maximal stretch of labelled stripes, each linked to the next with the next
    label; stretches shorter than a window are no evidence and dropped."""
    out = []
    i, n = 0, len(stripes)
    while i < n:
        if lab[i] < 0:
            i += 1
            continue
        i0 = i
        while i + 1 < n and stripes[i].linked and lab[i + 1] == (lab[i] + 1) % period:
            i += 1
        if i - i0 + 1 >= k:
            out.append((i0, i))
        i += 1
    return out


def _increasing(x: np.ndarray) -> None:
    """x made strictly increasing in place (a node not right of the one before moves 1e-3 px past it)."""
    for r in range(1, len(x)):
        if x[r] <= x[r - 1]:
            x[r] = x[r - 1] + 1e-3


def chain_nodes(stripes, lab, i0, i1, pattern: Pattern, lp: LabelParams) -> tuple[np.ndarray, np.ndarray]:
    """(camera x, projector column) of a chain's nodes: its inner stripe edges (edges mode; an edge is at
    projector column (label + 1) * sw - 0.5) or its stripe centres, increasing in x, smoothed by a local
    straight-line fit over +-smooth nodes (a surface is smooth within a chain; single edges are noisy)."""
    sw = pattern.stripe_width
    if lp.edges:
        nx = np.array([stripes[r].edge for r in range(i0, i1)], np.float64)
        nv = np.array([(lab[i0] + q + 1) * sw - 0.5 for q in range(i1 - i0)], np.float64)
    else:
        nx = np.array([0.5 * (np.ceil(s.left) + np.floor(s.right)) for s in stripes[i0 : i1 + 1]], np.float64)
        nv = np.array([(lab[i0] + q) * sw + 0.5 * (sw - 1) for q in range(i1 - i0 + 1)], np.float64)
    _increasing(nx)
    h = lp.smooth
    if h > 0 and len(nx) > 2 * h:
        fitted = np.empty_like(nx)
        for r in range(len(nx)):
            a0 = min(max(r - h, 0), len(nx) - 1 - 2 * h)  # the window of 2h + 1 nodes, kept inside the chain
            v, x = nv[a0 : a0 + 2 * h + 1], nx[a0 : a0 + 2 * h + 1]
            dv = v - v.mean()  # the least-squares line through the window's nodes (np.polyfit's, without its cost)
            fitted[r] = x.mean() + (dv @ (x - x.mean())) / (dv @ dv) * (nv[r] - v.mean())
        nx = fitted
        _increasing(nx)
    return nx, nv


def copy_vote(nx, nv, y, pattern: Pattern, column_range, min_frac: float) -> float | None:
    """The projector column shift (copy * period * sw) of the sequence copy the chain lies in: each node votes
    for the copies that put its column inside its pixel's depth-range interval (and on the projector). The
    chain takes a clear winner: the most votes, at least min_frac of the nodes, and no other copy with more
    than half as many; else None (ambiguous or outside the range). Without a range: copy 0."""
    if column_range is None:
        return 0.0
    W = column_range[0].shape[1]
    span = pattern.period * pattern.stripe_width
    px = np.clip(np.floor(nx + 0.5).astype(int), 0, W - 1)
    lo, hi = column_range[0][y, px], column_range[1][y, px]
    votes = []
    for q in range(pattern.n_copies):
        v = nv + q * span
        votes.append(int(((v >= lo) & (v <= hi) & (v <= pattern.proj_width - 0.5)).sum()))
    order = np.argsort(votes, kind="stable")[::-1]
    best = votes[order[0]]
    second = votes[order[1]] if len(votes) > 1 else 0
    if best == 0 or best < min_frac * len(nx) or second > 0.5 * best:
        return None
    return float(order[0] * span)


# ------------------------------------------------------------------------------------ 6. column write


def write_chain(col, chain_id, cid, y, stripes, i0, i1, nx, nv, shift, pattern: Pattern, column_range) -> None:
    """The chain's columns on its pixels (first pixel of its first stripe to last of its last): linear between
    neighbouring nodes (the first and last segments extended outwards), kept within END_EXT stripes beyond
    the outer nodes (the end stripes' own pixels) and inside each pixel's depth-range interval."""
    W = col.shape[1]
    sw = pattern.stripe_width
    xa = max(int(np.ceil(stripes[i0].left)), 0)
    xb = min(int(np.floor(stripes[i1].right)), W - 1)
    if xb < xa:
        return
    xr = np.arange(xa, xb + 1, dtype=np.float64)
    seg = np.clip(np.searchsorted(nx, xr, side="left") - 1, 0, len(nx) - 2)
    vals = nv[seg] + (xr - nx[seg]) * (nv[seg + 1] - nv[seg]) / (nx[seg + 1] - nx[seg]) + shift
    # the tests are on the value as stored (float32): a pixel exactly half a stripe beyond an outer stripe
    # centre (regular stripes, edges=False) is then kept or not by its stored column, not by float64 rounding
    vals = vals.astype(np.float32)
    span_lo = np.float32(nv[0] + shift - END_EXT * sw)
    span_hi = np.float32(nv[-1] + shift + END_EXT * sw)
    keep = (vals >= span_lo) & (vals <= span_hi)
    if column_range is not None:
        keep &= (vals >= column_range[0][y, xa : xb + 1]) & (vals <= column_range[1][y, xa : xb + 1])
    xs = xr[keep].astype(int)
    col[y, xs] = vals[keep]
    chain_id[y, xs] = cid


def label_rows(
    code: np.ndarray,
    feat: np.ndarray,
    thr: np.ndarray | None,
    pattern: Pattern,
    lp: LabelParams,
    column_range: tuple[np.ndarray, np.ndarray] | None,
    events: bool,
) -> StripeMap:
    """Stages 2-7 for every row: stripes (events, or code runs) -> windows -> confirmed labels -> chains ->
    copy vote -> columns, then the vertical check over the whole map."""
    H, W, _ = feat.shape
    column_range = _as_range(column_range)
    col = np.full((H, W), np.nan, np.float32)
    chain_id = np.full((H, W), -1, np.int32)
    n_chains = 0
    for y in range(H):
        if events:
            stripes = event_stripes(feat[y], thr[y], lp.gap_max)
        else:
            stripes = run_stripes(code[y], feat[y], pattern, lp.gap_max)
        if len(stripes) < pattern.k:
            continue
        lab = confirmed_labels(window_positions(stripes, pattern), pattern.k, pattern.period)
        for i0, i1 in chains(stripes, lab, pattern.k, pattern.period):
            nx, nv = chain_nodes(stripes, lab, i0, i1, pattern, lp)
            if len(nx) < 2:
                continue  # no segment to interpolate on
            shift = copy_vote(nx, nv, y, pattern, column_range, lp.min_frac)
            if shift is None:
                continue
            write_chain(col, chain_id, n_chains, y, stripes, i0, i1, nx, nv, shift, pattern, column_range)
            n_chains += 1
    n_dropped = vertical_check(col, chain_id, n_chains, lp)
    return StripeMap(
        col,
        np.isfinite(col).astype(np.float32),
        stripe_width=pattern.stripe_width,
        period=pattern.period,
        copy_known=column_range is not None or pattern.n_copies == 1,
        chain=chain_id,
        info={"chains": n_chains, "chains_dropped": n_dropped},
    )


# --------------------------------------------------------------------------------- 7. vertical check


def vertical_check(col: np.ndarray, chain_id: np.ndarray, n_chains: int, lp: LabelParams) -> int:
    """Keep a chain only where the rows above and below confirm it (in place; returns how many are dropped).

    Every decoded neighbour (y +- 1, same x) within vertical_tol projector px agrees, any other disagrees; a
    chain needs more agreements than disagreements and at least min_support agreements per pixel. A chain of
    noise can match the sequence by chance; it never lines up with the rows next to it. The counts are taken
    before any chain is dropped."""
    if lp.vertical_tol <= 0 or not n_chains:
        return 0
    H = col.shape[0]
    agree = np.zeros(n_chains, np.int64)
    disagree = np.zeros(n_chains, np.int64)
    for dy in (-1, 1):
        here = slice(max(0, -dy), H - max(0, dy))
        there = slice(max(0, dy), H - max(0, -dy))
        a, b = chain_id[here], chain_id[there]
        both = (a >= 0) & (b >= 0)
        close = both & (np.abs(col[here] - col[there]) <= lp.vertical_tol)
        np.add.at(agree, a[close], 1)
        np.add.at(disagree, a[both & ~close], 1)
    npx = np.bincount(chain_id[chain_id >= 0], minlength=n_chains)
    drop = (disagree >= agree) | (agree < lp.min_support * npx)
    bad = (chain_id >= 0) & drop[np.maximum(chain_id, 0)]
    col[bad] = np.nan
    chain_id[bad] = -1
    return int(drop.sum())


# ------------------------------------------------------------------------------------- 8. merge ("both")


def merge(a: StripeMap, b: StripeMap) -> StripeMap:
    """The events' map a with its missing values filled from the runs' map b; where both have a value and they
    differ by more than MERGE_TOL, none (one of them is wrong and nothing tells which)."""
    fill = np.isnan(a.column) & np.isfinite(b.column)
    clash = np.abs(a.column - b.column) > MERGE_TOL  # (False where either is NaN)
    a.column[fill] = b.column[fill]
    a.column[clash] = np.nan
    a.confidence = np.isfinite(a.column).astype(np.float32)
    a.chain[clash] = -1
    a.chain[fill] = b.chain[fill] + (int(a.chain.max()) + 1)
    a.info = {"events": a.info, "runs": b.info, "filled": int(fill.sum()), "clashes": int(clash.sum())}
    return a
