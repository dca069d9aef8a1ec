"""One-shot decoder (paper section 3): one frame of R/G/B stripes, colour classification per pixel.

Classification, after linearising and unmixing the camera crosstalk: by default each primary is
normalised by its own local min and max along the row (a few stripes' worth), which discounts
ambient light and moderate surface colour per channel; `use_hue=True` gives the paper's
chromaticity (hue-like) classifier instead, kept for the measured comparison. Stripes are pixel
runs of one colour, identified by windows of k, the edge between two colours at the zero crossing
of their normalised difference. The one-shot sequence repeats across the projector (192 stripes
for RGB, k = 7): the copy is chosen per chain from the calibrated depth range (see
`app/decode/windows.py`), and a chain whose columns fit more than one copy gets no value.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.decode import fast
from app.decode.colour import linearisation, unmixing_matrix
from app.decode.mirror import columns_run_backwards, mirror_back, mirror_image, mirror_range
from app.decode.stripemap import StripeMap
from app.decode.windows import LabelParams, WindowSpec, label, window_lookup
from app.errors import InputError
from app.patterns import CHANNEL_INDEX


@dataclass(frozen=True)
class OneShotParams:
    t_abs: float = 8.0  # minimum local span of a primary (linear, 8-bit units) to classify at all
    t_margin: float = 0.15  # best minus second-best normalised level
    block: int = 8
    use_hue: bool = False
    label: LabelParams = field(default_factory=lambda: LabelParams(gap_max=2))


def one_shot_spec(pattern_params: dict, proj_width: int) -> tuple[WindowSpec, np.ndarray]:
    colours = str(pattern_params["colors"]).upper()
    if not set(colours) <= set(CHANNEL_INDEX):
        raise InputError(f"one-shot decoding supports primary colours R, G, B only, not {colours!r}")
    seq = [int(v) for v in pattern_params["sequence"]]
    k = int(pattern_params["k"])
    N = len(colours)
    rows = np.array([CHANNEL_INDEX[c] for c in colours], np.int64)
    link_ok = ~np.eye(N, dtype=np.bool_)
    weights = np.zeros((N, N, 3), np.float32)
    for a in range(N):
        for b in range(N):
            if a != b:
                weights[a, b, rows[a]] = 1.0
                weights[a, b, rows[b]] = -1.0
    spec = WindowSpec(
        window_lookup(seq, k, N), link_ok, weights, k, len(seq), int(pattern_params["stripe_width"]), proj_width
    )
    return spec, rows


class OneShotDecoder:
    shots = 1

    def __init__(
        self,
        pattern_params: dict,
        proj_width: int,
        color_mixing: np.ndarray | None = None,
        column_range: tuple[np.ndarray, np.ndarray] | None = None,
        params: OneShotParams | None = None,
        camera_gamma: float = 1.0,
    ) -> None:
        self.params = params or OneShotParams()
        self.spec, self.rows = one_shot_spec(pattern_params, proj_width)
        self.sequence = tuple(int(v) for v in pattern_params["sequence"])
        self.unmix = unmixing_matrix(color_mixing)
        # a rig whose columns run right to left decodes the mirrored image (app/decode/mirror.py)
        self.mirrored = columns_run_backwards(column_range)
        self.column_range = mirror_range(column_range) if self.mirrored else column_range
        self.camera_gamma = camera_gamma

    def classify(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype not in (np.uint8, np.uint16):
            raise InputError(f"one-shot frame must be uint8/uint16 RGB, found {image.dtype} {image.shape}")
        lin, _ = linearisation(65536 if image.dtype == np.uint16 else 256, self.camera_gamma)
        linear = np.stack([lin[c][image[..., c]] for c in range(3)], axis=-1)
        H, W = image.shape[:2]
        code = np.empty((H, W), np.int8)
        feat = np.empty((H, W, 3), np.float32)
        p = self.params
        fast.oneshot_classify(
            linear, self.unmix, self.rows, np.float32(p.t_abs), np.float32(p.t_margin), p.block, p.use_hue, code, feat
        )
        return code, feat

    def decode(self, image: np.ndarray) -> StripeMap:
        if self.mirrored:
            image = mirror_image(image)
        code, feat = self.classify(image)
        sm = label(code, feat, self.spec, self.params.label, self.column_range)
        return mirror_back(sm) if self.mirrored else sm
