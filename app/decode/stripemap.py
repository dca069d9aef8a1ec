"""The decoders' common output: a projector column per camera pixel, or none."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class StripeMap:
    """Per camera pixel: sub-pixel projector column (NaN = no value) and what it rests on.

    `column` is in projector pixels, pixel centres at integers (stripe s of width w covers
    columns s*w .. s*w+w-1). `chain` numbers the row segments a value was decoded from (-1 none; None from the
    fused two-shot decoder, which keeps only the rows its vertical check compares); `confidence` is 0 where
    there is no value, else in (0, 1] (made from the column when first read if the decoder gave None).
    """

    column: np.ndarray  # (H, W) float32, NaN where no value
    # (H, W) float32; None: 1 where a value, else 0 (what every decoder here gives), made when first read
    _confidence: np.ndarray | None = field(default=None, repr=False)
    stripe_width: int = 1
    period: int = 0  # stripes in one period of the sequence (0 = not periodic, e.g. Gray code)
    copy_known: bool = True  # False when no geometry was given to choose between repeated copies
    chain: np.ndarray | None = field(default=None, repr=False)
    info: dict = field(default_factory=dict)  # counts for logs and benches

    @property
    def confidence(self) -> np.ndarray:
        if self._confidence is None:
            self._confidence = np.isfinite(self.column).astype(np.float32)
        return self._confidence

    @confidence.setter
    def confidence(self, value: np.ndarray | None) -> None:
        self._confidence = value

    @property
    def has_confidence(self) -> bool:
        """Whether a confidence map was given or made (else reading it makes one)."""
        return self._confidence is not None

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.column)

    @property
    def stripe(self) -> np.ndarray:
        """Projector stripe number per pixel (-1 = none), for pseudo-colour displays."""
        out = np.full(self.column.shape, -1, np.int32)
        v = self.valid
        out[v] = np.floor((self.column[v] + 0.5) / self.stripe_width).astype(np.int32)
        return out

    @property
    def shape(self) -> tuple[int, int]:
        return self.column.shape  # type: ignore[return-value]
