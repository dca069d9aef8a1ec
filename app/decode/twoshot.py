"""Two-shot decoder (paper section 4): stripe codes from the signs of frame2 - frame1.

Per pixel and pattern channel, the unmixed difference d = frame2 - frame1 is negative where the
channel was at max in frame 1 (code bit 1) and positive where it was at min. Ambient light and
surface colour scale |d| but never flip its sign, so only |d| too small for a sign (shadow,
black surface, clipping in both frames, a stripe edge) gives no code. Adjacent stripes differ in
exactly one channel, whose d crosses zero at the edge: that zero crossing is the sub-pixel node.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.decode import fast
from app.decode.colour import channel_rows, linearisation, unmixing_matrix
from app.decode.fast.lacking import lacking_channel
from app.decode.fast.lacking_edges import NO_LACKING_EDGES
from app.decode.fast.lacking_leak import leak_channel
from app.decode.mirror import columns_run_backwards, mirror_back, mirror_image, mirror_range
from app.decode.mosaic_signs import lacking_signs
from app.decode.response_inverse import ResponseInverse, identity_inverse, response_inverse
from app.decode.stripemap import StripeMap
from app.decode.windows import EMPTY_RANGE, LabelParams, WindowSpec, label_settings, window_lookup
from app.errors import InputError


@dataclass(frozen=True)
class TwoShotParams:
    t_abs: float = 2.0  # noise floor of |d| in raw 8-bit camera steps (carried through the response slope)
    t_rel: float = 0.03  # runs: a code needs |d| of this share of the channel's local amplitude
    block: int = 8  # pixels per block of the local-amplitude estimate
    t_rel_edges: float = 0.03  # events: a sign (either side of a zero crossing) needs this share
    # "runs": stripes are pixel runs of one code, with sub-pixel edges at the zero crossing between
    # them. "events": stripes are the intervals between per-channel zero crossings. "both": the two
    # merged (values of one where the other has none; where they disagree by > 0.5 px, none).
    # Measured on the virtual rig's six bench scenes (`slscan bench --accuracy`): "runs" at t_rel 0.03
    # meets every target at half the time of "both" (at t_rel 0.2), whose coverage is at most 0.8 %
    # higher and whose correct rate is within 0.12 % (higher on the cube, lower on the face); "events"
    # alone misses 90 % coverage on the cube and the cylinder. (At t_rel 0.2, "runs" alone missed it
    # on the saturated colour panel.)
    segmentation: str = "runs"
    label: LabelParams = field(default_factory=LabelParams)


SEGMENTATIONS = fast.MODES  # fast.twoshot_rows' mode numbers

# a triangulator's closed-form geometry: Moebius planes (3, H, W) float32, w0, w_span (Triangulator.moebius_geometry)
MoebiusGeometry = tuple[np.ndarray, float, float]
NO_PLANES = np.zeros((3, 1, 1), np.float32)  # (what twoshot_rows takes for no depth map)
NO_DEPTH = np.zeros((0, 0), np.float32)  # (no frame of 0 x 0 pixels has rows to triangulate)


def two_shot_spec(pattern_params: dict, proj_width: int) -> WindowSpec:
    seq = [int(v) for v in pattern_params["sequence"]]
    m = len(pattern_params["channels"])
    k = int(pattern_params["k"])
    A = 1 << m
    link_ok = np.zeros((A, A), np.bool_)
    weights = np.zeros((A, A, m), np.float32)
    for a in range(A):
        for b in range(A):
            diff = a ^ b
            if diff.bit_count() == 1:
                link_ok[a, b] = True
                c = diff.bit_length() - 1
                weights[a, b, c] = -1.0 if (a >> c) & 1 else 1.0  # bit 1 = d < 0 on the a side
    return WindowSpec(
        window_lookup(seq, k, A), link_ok, weights, k, len(seq), int(pattern_params["stripe_width"]), proj_width
    )


class TwoShotDecoder:
    """Decode (frame 1, frame 2) pairs of one pattern export, optionally with depth-range geometry."""

    shots = 2

    def __init__(
        self,
        pattern_params: dict,
        proj_width: int,
        color_mixing: np.ndarray | None = None,
        column_range: tuple[np.ndarray, np.ndarray] | None = None,
        params: TwoShotParams | None = None,
        camera_gamma: float = 1.0,
        camera_response: np.ndarray | None = None,
    ) -> None:
        self.params = params or TwoShotParams()
        self.spec = two_shot_spec(pattern_params, proj_width)
        self.sequence = tuple(int(v) for v in pattern_params["sequence"])
        self.channels = str(pattern_params["channels"])
        self.unmix = channel_rows(unmixing_matrix(color_mixing), self.channels)
        if column_range is not None:  # (what the row kernel reads: float32, C order)
            column_range = tuple(np.ascontiguousarray(r, np.float32) for r in column_range)
        # a rig whose columns run right to left decodes the mirrored image (app/decode/mirror.py)
        self.mirrored = columns_run_backwards(column_range)
        self.column_range = mirror_range(column_range) if self.mirrored else column_range
        self.camera_gamma = camera_gamma
        self.camera_response = camera_response
        self._luts: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._packed: dict[int, np.ndarray] = {}
        self._inverses: dict[int, ResponseInverse] = {}
        self._bundles: dict[tuple, tuple] = {}
        # frames reconstructed from this raw Bayer mosaic (app/decode/mosaic.py): the lacking channel's signs come
        # from the G edges where its columns alias the stripes (fast/lacking.py); None for other frames
        self.mosaic: str | None = None
        # the pairs given already carry the lacking channel's signs (mosaic_signs.lacking_signs, a pass of its own),
        # so the row loop takes none; its edges are still placed from the G edges (fast/lacking_edges.py)
        self.signs_taken = False

    def luts(self, dtype: np.dtype) -> tuple[np.ndarray, np.ndarray]:
        levels = 65536 if dtype == np.uint16 else 256
        if levels not in self._luts:
            resp = self.camera_response
            if resp is not None and np.asarray(resp).shape[-1] != levels:
                resp = None
            self._luts[levels] = linearisation(levels, self.camera_gamma, resp)
        return self._luts[levels]

    def tables(self, dtype: np.dtype) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """luts(dtype) and the table the row kernel reads them from (fast.pair_tables for 8-bit frames: one
        gather per channel for both frames; else fast.pack_tables), built once per frame depth."""
        lin, dlin = self.luts(dtype)
        levels = lin.shape[1]
        if levels not in self._packed:
            pairs = fast.pair_tables(lin, dlin)
            self._packed[levels] = pairs if pairs.size else fast.pack_tables(lin, dlin)
        return lin, dlin, self._packed[levels]

    def inverse(self, dtype: np.dtype) -> ResponseInverse:
        """The inverse of luts(dtype)'s camera response (app/decode/response_inverse.py), built once per depth."""
        lin = self.luts(dtype)[0]
        levels = lin.shape[1]
        if levels not in self._inverses:
            self._inverses[levels] = response_inverse(lin)
        return self._inverses[levels]

    def bundles(self, dtype: np.dtype, use_range: bool) -> tuple:
        """What fast.twoshot_rows reads besides the frames, the geometry and the maps: (FrameTables, Classifier,
        StripeCode, LabelSettings), built once per frame depth and parameters (the per-frame call passes them as
        they are)."""
        p = self.params
        # (mirrored rigs take the signs in a pass of their own before the mirror: decode)
        lacking = lacking_channel(self.channels, None if self.mirrored or self.signs_taken else self.mosaic)
        # (the lacking channel's edges from the G edges, mirrored or not: lacking_edges.py needs no column parity)
        ig = lacking_channel(self.channels, self.mosaic)[0]
        lacking_bit = 1 << (1 - ig) if ig >= 0 else NO_LACKING_EDGES
        leak = leak_channel(self.channels, self.mosaic, self.mirrored)  # (the leak into G: every path, lacking_leak.py)
        key = (np.dtype(dtype), p, use_range, lacking, lacking_bit, leak)
        if key not in self._bundles:
            # (the inverse serves a raw mosaic's fill only: other frames need no increasing response)
            inverse = self.inverse(dtype) if self.mosaic is not None else identity_inverse(dtype)
            tables = fast.FrameTables(*self.tables(dtype), inverse)
            classifier = fast.Classifier(
                self.unmix,
                np.float32(p.t_abs),
                np.float32(p.t_rel),
                np.float32(p.t_rel_edges),
                int(p.block),
                lacking,
                leak,
            )
            settings = label_settings(self.spec, p.label, use_range, lacking_bit)
            self._bundles[key] = (tables, classifier, self.spec.stripe_code(), settings)
        return self._bundles[key]

    @staticmethod
    def _check_pair(frame1: np.ndarray, frame2: np.ndarray) -> None:
        if frame1.shape != frame2.shape or frame1.ndim != 3 or frame1.shape[2] != 3:
            raise InputError(f"frames of a pair differ in size or are not RGB: {frame1.shape} vs {frame2.shape}")
        if frame1.dtype not in (np.uint8, np.uint16) or frame2.dtype != frame1.dtype:
            raise InputError(f"frames must both be uint8 or uint16 RGB, found {frame1.dtype} and {frame2.dtype}")

    def classify(self, frame1: np.ndarray, frame2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-pixel codes (-1 = none), the unmixed differences and the event mode's sign thresholds, as full
        images: the specification the fused path (decode) is tested against, step by step."""
        self._check_pair(frame1, frame2)
        H, W = frame1.shape[:2]
        m = self.unmix.shape[0]
        code = np.empty((H, W), np.int8)
        feat = np.empty((H, W, m), np.float32)
        noise = np.empty((H, W, m), np.float32)
        lin, dlin = self.luts(frame1.dtype)
        p = self.params
        fast.twoshot_classify(
            frame1,
            frame2,
            lin,
            dlin,
            self.unmix,
            np.float32(p.t_abs),
            np.float32(p.t_rel),
            np.float32(p.t_rel_edges),
            p.block,
            code,
            feat,
            noise,
        )
        return code, feat, noise

    def decode(self, frame1: np.ndarray, frame2: np.ndarray) -> StripeMap:
        """frame1 saw pattern 0 and frame2 pattern 1 (in pattern order, whichever came first in time)."""
        if self.mirrored:
            frame1, frame2 = self._mirrored_signs(frame1, frame2)
            return mirror_back(self._decode(mirror_image(frame1), mirror_image(frame2))[0])
        return self._decode(frame1, frame2)[0]

    def decode_depth(
        self, frame1: np.ndarray, frame2: np.ndarray, geometry: MoebiusGeometry
    ) -> tuple[StripeMap, np.ndarray | None]:
        """decode(), and the depth map (float32 mm, 0 = none) from a triangulator's closed-form geometry
        (Triangulator.moebius_geometry) in the same pass: each row is triangulated as soon as its columns are
        final, while it is in cache; the same depths as Triangulator.depth of the stripe map. None for a rig
        decoded mirrored (the caller triangulates the stripe map)."""
        if self.mirrored:
            frame1, frame2 = self._mirrored_signs(frame1, frame2)
            return mirror_back(self._decode(mirror_image(frame1), mirror_image(frame2))[0]), None
        return self._decode(frame1, frame2, geometry)

    def _mirrored_signs(self, frame1: np.ndarray, frame2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A rig decoded mirrored: the pair with a raw mosaic's lacking signs from the G edges (mosaic_signs.py, the
        fused path's specification, on the frames as the camera saw them), as it is without a mosaic."""
        if self.mosaic is None or self.signs_taken:
            return frame1, frame2
        self._check_pair(frame1, frame2)
        return lacking_signs(frame1, frame2, self.mosaic, self)

    def _decode(
        self, frame1: np.ndarray, frame2: np.ndarray, geometry: MoebiusGeometry | None = None
    ) -> tuple[StripeMap, np.ndarray | None]:
        """Every segmentation, fused row by row (no full-image codes or differences): the same result as
        label() of the events or the runs, and for "both" label(runs) merged into label(events) by merge_maps;
        with geometry, the depth map too (see decode_depth)."""
        self._check_pair(frame1, frame2)
        # the kernels take C-contiguous frames: a view (a crop, cv2's BGR flipped by frame[..., ::-1]) is copied, a
        # fraction of a millisecond, rather than compiled for its layout (a minute, once) into the scalar loops
        frame1 = np.ascontiguousarray(frame1)
        frame2 = np.ascontiguousarray(frame2)
        H, W = frame1.shape[:2]
        if geometry is None:
            planes, w0, w_span = NO_PLANES, 0.0, 0.0
            depth = NO_DEPTH
        else:
            planes, w0, w_span = geometry
            planes = np.ascontiguousarray(planes, np.float32)
            if planes.shape != (3, H, W):
                raise InputError(f"frames are {W}x{H}, calibration camera is {planes.shape[2]}x{planes.shape[1]}")
            depth = np.empty((H, W), np.float32)
        p, spec = self.params, self.spec
        if p.segmentation not in SEGMENTATIONS:
            raise ValueError(f"segmentation {p.segmentation!r} is not one of {', '.join(SEGMENTATIONS)}")
        use_range = self.column_range is not None
        tables, classifier, stripes, settings = self.bundles(frame1.dtype, use_range)
        lo, hi = self.column_range if use_range else (EMPTY_RANGE, EMPTY_RANGE)
        # all written by the kernel, row by row
        col_e = np.empty((H, W), np.float32)
        # the chain maps hold the last two rows only (the rows the vertical check compares): the fused path outputs
        # no chain map (a full one was a fourth map written per frame, read by nothing in the product)
        chain_e = np.empty((2, W), np.int32)
        both = p.segmentation == "both"
        # the second map and the merge are used by "both" only
        col_r = np.empty((H, W), np.float32) if both else EMPTY_RANGE
        chain_r = np.empty((2, W), np.int32) if both else np.full((1, 1), -1, np.int32)
        n_e, n_r, drop_e, drop_r, filled, clashes = fast.twoshot_rows(
            frame1,
            frame2,
            tables,
            classifier,
            stripes,
            settings,
            SEGMENTATIONS.index(p.segmentation),
            fast.Geometry(lo, hi, planes, np.float32(w0), np.float32(w_span), depth),
            col_e,
            chain_e,
            col_r,
            chain_r,
        )
        sm = StripeMap(
            col_e,
            None,  # (confidence: 1 where a value, made when read)
            stripe_width=spec.stripe_width,
            period=spec.period,
            copy_known=use_range or spec.n_copies == 1,
            chain=None,
            info=(
                {"chains": int(n_e), "chains_dropped": int(drop_e)}
                if not both
                else {
                    "events": {"chains": int(n_e), "chains_dropped": int(drop_e)},
                    "runs": {"chains": int(n_r), "chains_dropped": int(drop_r)},
                    "filled": int(filled),
                    "clashes": int(clashes),
                }
            ),
        )
        return sm, (depth if geometry is not None else None)


def merge_maps(a: StripeMap, b: StripeMap, tol: float = 0.5) -> None:
    """Fill a's missing values from b; where both have one and they differ by more than tol, none (in place)."""
    fill = np.isnan(a.column) & np.isfinite(b.column)
    clash = np.abs(a.column - b.column) > tol  # False where either is NaN
    a.column[fill] = b.column[fill]
    a.column[clash] = np.nan
    a.confidence[fill] = b.confidence[fill]
    a.confidence[clash] = 0.0
    if a.chain is not None:
        a.chain[clash] = -1
        if b.chain is not None:
            a.chain[fill] = b.chain[fill] + (int(a.chain.max()) + 1)
    a.info = {"events": a.info, "runs": b.info, "filled": int(fill.sum()), "clashes": int(clash.sum())}
