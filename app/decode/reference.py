"""Plain numpy/Python reference of the colour decoders, written for reading, not speed.

It follows the same specification as the compiled path (`app/decode/kernels.py` via
`TwoShotDecoder` and `OneShotDecoder`) step by step; the tests run both on the same frames and
compare: classification (`classify`, `classify_one_shot`) and labelling (`label_rows`: windows,
confirmed labels, chains, sub-pixel columns, copy choice, vertical check).
"""

from __future__ import annotations

import numpy as np

from app.decode.colour import linearisation
from app.decode.oneshot import OneShotDecoder
from app.decode.stripemap import StripeMap
from app.decode.twoshot import TwoShotDecoder
from app.patterns import window_table


def classify(dec: TwoShotDecoder, f1: np.ndarray, f2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-pixel codes (-1 = none), unmixed linear differences (H, W, m), sign thresholds (event mode)."""
    lin, dlin = dec.luts(f1.dtype)
    ch = np.arange(3)
    d = lin[ch, f2] - lin[ch, f1]  # (H, W, 3)
    slope = dlin[ch, f2] + dlin[ch, f1]
    U = dec.unmix.astype(np.float32)
    feat = np.einsum("cj,hwj->hwc", U, d).astype(np.float32)
    noise = (dec.params.t_abs * 0.5 * np.einsum("cj,hwj->hwc", np.abs(U), slope)).astype(np.float32)
    H, W, m = feat.shape
    block = dec.params.block
    nb = -(-W // block)
    pad = np.zeros((H, nb * block, m), np.float32)
    pad[:, :W] = np.abs(feat)
    bmax = pad.reshape(H, nb, block, m).max(axis=2)
    left = np.concatenate([bmax[:, :1] * 0, bmax[:, :-1]], axis=1)
    right = np.concatenate([bmax[:, 1:], bmax[:, :1] * 0], axis=1)
    amp = np.maximum(bmax, np.maximum(left, right))[:, np.arange(W) // block]
    thr = np.maximum(noise, dec.params.t_rel_edges * amp)
    signed = np.abs(feat) >= np.maximum(noise, dec.params.t_rel * amp)
    bits = ((feat < 0) << np.arange(m)).sum(axis=2)
    code = np.where(signed.all(axis=2), bits, -1)
    return code, feat, thr


def _channel_events(d: np.ndarray, thr: np.ndarray, gap_max: int) -> list[tuple[float, int, int]]:
    """(position, kind, sign) with kind 0 = becomes known, 1 = sign change, 2 = unknown."""
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
            k = np.flatnonzero((seg[:-1] > 0) != (seg[1:] > 0))
            j = px + k[0] if len(k) else px
            a, b = (d[j], d[j + 1]) if len(k) else (d[px], d[x])
            out.append((j + a / (a - b) * (1 if len(k) else x - px), 1, int(s[x])))
    if len(xs):
        out.append((xs[-1] + 0.5, 2, 0))
    return out


def _intervals(feat_row: np.ndarray, thr_row: np.ndarray, gap_max: int):
    m = feat_row.shape[1]
    events = []
    for c in range(m):
        events += [(x, c, kind, s) for x, kind, s in _channel_events(feat_row[:, c], thr_row[:, c], gap_max)]
    events.sort(key=lambda e: (e[0], e[1]))
    sign = [0] * m
    iv: list[list] = []  # [left, right, code, linked_to_previous]
    active = False
    for x, c, kind, s in events:
        if active:
            iv[-1][1] = x
        was = active
        sign[c] = s
        active = all(sign)
        if active:
            code = sum(1 << i for i in range(m) if sign[i] < 0)
            iv.append([x, x, code, was and kind == 1])
    return [[a, b, c, lk, b] for a, b, c, lk in iv]  # the edge after a stripe is where it ends


def _runs(code_row: np.ndarray, feat_row: np.ndarray, spec, gap_max: int):
    """Intervals from pixel runs of one code; edges at the zero crossing of the flipping channel."""
    iv: list[list] = []
    x, W = 0, len(code_row)
    while x < W:
        if code_row[x] < 0:
            x += 1
            continue
        s = x
        while x + 1 < W and code_row[x + 1] == code_row[s]:
            x += 1
        iv.append([s, x, int(code_row[s])])
        x += 1
    out = []
    for j, (rs, re, c) in enumerate(iv):
        linked = False
        if j > 0:
            _, pre, pc = iv[j - 1]
            linked = bool(rs - pre - 1 <= gap_max and spec.link_ok[pc, c])
        out.append([rs - 0.5, re + 0.5, c, linked, re + 0.5])
    for j in range(len(iv) - 1):
        if not out[j + 1][3]:
            continue
        rs, re, a = iv[j]
        nrs, nre, b = iv[j + 1]
        xa = re - 1 if re - 1 >= rs else re
        xb = nrs + 1 if nrs + 1 <= nre else nrs
        mid = 0.5 * (re + nrs)
        sig = feat_row @ spec.weights[a, b]
        best, bestd = mid, 1e9
        for xx in range(xa, xb):
            s0, s1 = sig[xx], sig[xx + 1]
            if s0 > 0 and s1 <= 0:
                xz = xx + s0 / (s0 - s1)
                if abs(xz - mid) < bestd:
                    best, bestd = xz, abs(xz - mid)
        out[j][4] = best
    return out


def decode(dec: TwoShotDecoder, f1: np.ndarray, f2: np.ndarray) -> StripeMap:
    """The decoder's segmentation setting: 'events', 'runs' or 'both' (merged)."""
    seg = dec.params.segmentation
    if seg == "both":
        a = _decode(dec, f1, f2, True)
        b = _decode(dec, f1, f2, False)
        fill = np.isnan(a.column) & np.isfinite(b.column)
        clash = np.abs(a.column - b.column) > 0.5
        a.column[fill] = b.column[fill]
        a.column[clash] = np.nan
        return a
    return _decode(dec, f1, f2, seg == "events")


def _decode(dec: TwoShotDecoder, f1: np.ndarray, f2: np.ndarray, events: bool) -> StripeMap:
    code, feat, thr = classify(dec, f1, f2)
    return label_rows(code, feat, thr, dec.spec, dec.params.label, dec.column_range, dec.sequence, events)


def classify_one_shot(dec: OneShotDecoder, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel colour index into the pattern's colours (-1 = none) and the normalised levels (H, W, 3)."""
    p = dec.params
    lin, _ = linearisation(65536 if image.dtype == np.uint16 else 256, dec.camera_gamma)
    linear = np.stack([lin[c][image[..., c]] for c in range(3)], axis=-1).astype(np.float32)
    u = np.einsum("cj,hwj->hwc", dec.unmix.astype(np.float32), linear).astype(np.float32)
    H, W, _ = u.shape
    if p.use_hue:
        v = np.maximum(u, 0)
        total = v.sum(axis=2, keepdims=True)
        feat = np.where(total >= p.t_abs, v / np.where(total > 0, total, 1), 0).astype(np.float32)
    else:
        # each unmixed primary rescaled by its own min and max over this block and its two neighbours
        nb = -(-W // p.block)
        pad_hi = np.full((H, nb * p.block, 3), -np.inf, np.float32)
        pad_lo = np.full((H, nb * p.block, 3), np.inf, np.float32)
        pad_hi[:, :W] = u
        pad_lo[:, :W] = u
        bmax = pad_hi.reshape(H, nb, p.block, 3).max(axis=2)
        bmin = pad_lo.reshape(H, nb, p.block, 3).min(axis=2)
        hi = _with_neighbours(bmax, np.maximum, -np.inf)
        lo = _with_neighbours(bmin, np.minimum, np.inf)
        hi, lo = hi[:, np.arange(W) // p.block], lo[:, np.arange(W) // p.block]
        span = hi - lo
        feat = np.where(span >= p.t_abs, (u - lo) / np.where(span > 0, span, 1), 0).astype(np.float32)
    levels = feat[..., dec.rows]  # (H, W, N) in the pattern's colour order
    order = np.argsort(-levels, axis=2, kind="stable")
    v1 = np.take_along_axis(levels, order[..., :1], 2)[..., 0]
    v2 = np.take_along_axis(levels, order[..., 1:2], 2)[..., 0] if levels.shape[2] > 1 else np.full_like(v1, -1)
    code = np.where((v1 - v2 >= p.t_margin) & (v1 > 0), order[..., 0], -1)
    return code, feat


def _with_neighbours(blocks: np.ndarray, op, pad: float) -> np.ndarray:
    """op (max or min) of each block's value and its left and right neighbours' along axis 1."""
    edge = np.full_like(blocks[:, :1], pad)
    return op(blocks, op(np.concatenate([edge, blocks[:, :-1]], 1), np.concatenate([blocks[:, 1:], edge], 1)))


def label_rows(
    code: np.ndarray,
    feat: np.ndarray,
    thr: np.ndarray | None,
    spec,
    lp,
    column_range: tuple[np.ndarray, np.ndarray] | None,
    sequence,
    events: bool,
) -> StripeMap:
    """Stripes of each row (sign-change intervals or code runs) -> windows -> chains -> columns, then
    the vertical check: what kernels.label_rows + vertical_check (and the fused two-shot path) do."""
    H, W, _ = feat.shape
    table = window_table(sequence, spec.k)
    P, k, sw = spec.period, spec.k, spec.stripe_width
    col = np.full((H, W), np.nan, np.float32)
    chain_id = np.full((H, W), -1, np.int32)
    n_chains = 0
    for y in range(H):
        iv = _intervals(feat[y], thr[y], lp.gap_max) if events else _runs(code[y], feat[y], spec, lp.gap_max)
        n = len(iv)
        codes = [v[2] for v in iv]
        linked = [iv[j + 1][3] for j in range(n - 1)] + [False]
        pos = [
            table.get(tuple(codes[j : j + k]), -1) if j + k <= n and all(linked[j : j + k - 1]) else -1
            for j in range(n)
        ]
        lab = [-1] * n
        for j in range(n):
            p = pos[j]
            if p < 0:
                continue
            nxt = j + 1 < n and pos[j + 1] == (p + 1) % P
            prv = j > 0 and pos[j - 1] >= 0 and p == (pos[j - 1] + 1) % P
            if not (nxt or prv):
                continue
            for t in range(k):
                lv = (p + t) % P
                lab[j + t] = lv if lab[j + t] in (-1, lv) else -2
        i = 0
        while i < n:
            if lab[i] < 0:
                i += 1
                continue
            i0 = i
            while i + 1 < n and linked[i] and lab[i + 1] == (lab[i] + 1) % P:
                i += 1
            i1 = i
            i += 1
            if i1 - i0 + 1 < k:
                continue
            nx = np.array([iv[r][4] for r in range(i0, i1)], np.float64)
            nv = np.array([(lab[i0] + r - i0 + 1) * sw - 0.5 for r in range(i0, i1)], np.float64)
            for r in range(1, len(nx)):
                if nx[r] <= nx[r - 1]:
                    nx[r] = nx[r - 1] + 1e-3
            h = lp.smooth
            if h > 0 and len(nx) > 2 * h:
                sm = np.empty_like(nx)
                for r in range(len(nx)):
                    a0 = min(max(r - h, 0), len(nx) - 1 - 2 * h)
                    slope, icpt = np.polyfit(nv[a0 : a0 + 2 * h + 1], nx[a0 : a0 + 2 * h + 1], 1)
                    sm[r] = icpt + slope * nv[r]
                nx = sm
            for r in range(1, len(nx)):
                if nx[r] <= nx[r - 1]:
                    nx[r] = nx[r - 1] + 1e-3
            xa = max(int(np.ceil(iv[i0][0])), 0)
            xb = min(int(np.floor(iv[i1][1])), W - 1)
            if xb < xa:
                continue
            xr = np.arange(xa, xb + 1, dtype=np.float64)
            seg = np.clip(np.searchsorted(nx, xr, side="left") - 1, 0, len(nx) - 2)
            vals = nv[seg] + (xr - nx[seg]) * (nv[seg + 1] - nv[seg]) / (nx[seg + 1] - nx[seg])
            keep = (vals >= nv[0] - 0.5 * sw) & (vals <= nv[-1] + 0.5 * sw)
            shift = 0.0
            if column_range is not None:
                # the nodes vote for the copy that puts them inside their pixel's depth-range interval
                xn = np.clip(np.floor(nx + 0.5).astype(int), 0, W - 1)
                lo_n, hi_n = column_range[0][y, xn], column_range[1][y, xn]
                counts = []
                for q in range(spec.n_copies):
                    v = nv + q * P * sw
                    counts.append(int(((v >= lo_n) & (v <= hi_n) & (v <= spec.proj_width - 0.5)).sum()))
                order = np.argsort(counts, kind="stable")[::-1]
                best = counts[order[0]]
                second = counts[order[1]] if len(counts) > 1 else 0
                if best == 0 or best < lp.min_frac * len(nx) or second > 0.5 * best:
                    continue
                shift = order[0] * P * sw
                lo, hi = column_range[0][y, xa : xb + 1], column_range[1][y, xa : xb + 1]
                v = vals + shift
                keep &= (v >= lo) & (v <= hi)
            xs = xr[keep].astype(int)
            col[y, xs] = (vals[keep] + shift).astype(np.float32)
            chain_id[y, xs] = n_chains
            n_chains += 1
    # vertical support
    if lp.vertical_tol > 0 and n_chains:
        agree = np.zeros(n_chains, np.int64)
        disagree = np.zeros(n_chains, np.int64)
        for dy in (-1, 1):
            a = chain_id[max(0, -dy) : H - max(0, dy)]
            b = chain_id[max(0, dy) : H - max(0, -dy)]
            ca = col[max(0, -dy) : H - max(0, dy)]
            cb = col[max(0, dy) : H - max(0, -dy)]
            both = (a >= 0) & (b >= 0)
            close = both & (np.abs(ca - cb) <= lp.vertical_tol)
            np.add.at(agree, a[close], 1)
            np.add.at(disagree, a[both & ~close], 1)
        npx = np.bincount(chain_id[chain_id >= 0], minlength=n_chains)
        drop = (disagree >= agree) | (agree < lp.min_support * npx)
        bad = (chain_id >= 0) & drop[np.maximum(chain_id, 0)]
        col[bad] = np.nan
        chain_id[bad] = -1
    return StripeMap(col, np.isfinite(col).astype(np.float32), stripe_width=sw, period=P, chain=chain_id)
