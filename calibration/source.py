"""What the wizard's window and state need from a rig: the `BoardSource` interface.

Two implementations: the virtual rig with a keyboard-moved board (calibration/sim_source.py) and
a rig opened from the driver registries, real or simulated devices alike (calibration/rig_source.py).
The window (calibration/wizard.py) and the bookkeeping (calibration/wizard_state.py) are shared.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from calibration.board import Board
from calibration.preview import PreviewWorker
from calibration.sequence import Take
from core.calibration import Calibration
from core.patterns import PatternSet


class BoardSource(Protocol):
    board: Board
    patterns: PatternSet  # the Gray-code sequence, as the capture layout records it
    meta: dict  # patterns.yaml of that sequence (what the decoder reads)
    preview: PreviewWorker  # the live view: newest camera image under white light + board detection
    movable: bool  # the board moves from the keyboard (the virtual rig: there is no hand to hold it)
    name: str  # what the window title and messages call the rig

    @property
    def camera_size(self) -> tuple[int, int]: ...
    @property
    def projector_size(self) -> tuple[int, int]: ...
    @property
    def camera_gamma(self) -> float | None: ...  # known camera response exponent, None = linear / unknown

    def capture(self) -> Take: ...  # the Gray-code sequence on the board as it is (raises PoseNotCaptured)
    def levels(self) -> list[tuple[str, int, np.ndarray]]: ...  # flat colour levels (channel, level, image)
    def validation_scan(self, cal: Calibration) -> str: ...  # scan the board held flat: one line of figures
    def pump(self) -> None: ...  # between redraws: keep a projector window of the rig responsive
    def close(self) -> None: ...
