"""Film a pattern sequence on real devices, exactly one checked camera frame per pattern.

The wizard's "capture pose" (Gray code) and "colour levels" (flat levels) on a rig opened from
the driver registries. A frame that saw the wrong pattern is never kept: the sequence is taken
again (up to a budget), and if no clean take comes, nothing is returned (PoseNotCapturedError).

With a trigger (the trigger box, or the virtual rig's): the live session's capture loop
(app/capture.py) cycles the patterns. Each frame is placed on the projector's schedule by its
trigger count and tagged from the flip record; dropped (frame_id gap), duplicated, swapped, late
and mistagged frames are refused, and with more than one cycle the pixels of each frame are
confirmed against the same pattern one cycle earlier (a late flip that no counter saw). A take
is the first unbroken, fully checked cycle 0..n-1. This is preferred to stepping because the
trigger count ties every exposure to a flip; a settle delay only guesses.

Without a trigger (a free-running camera): patterns are stepped one at a time: show, let
`settle` frames pass (the camera's pipeline latency), keep the next one; a frame_id that repeats
or goes back restarts the take. The take is then checked from its pixels (`check_graycode` /
`check_levels`): a frame that saw a neighbouring pattern breaks the inverse pairs or the level
order.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from app.capture import CaptureLoop
from app.decode.mosaic import to_rgb
from core.errors import DeviceError
from drivers.base import Camera, Projector, Trigger

MAX_TAKES = 6  # takes tried before a pose is given up (the operator retakes it): ~5 s at 60 Hz
IMPOSSIBLE_FRACTION = 0.01  # of lit pixels equal in a bit frame and its inverse: above, a frame saw another pattern
WHITE_RATIO = 0.8  # white - black against a bit + its inverse - 2 black (1 in a right take)


class PoseNotCapturedError(DeviceError):
    """No clean take of the sequence within the budget (frames kept being refused)."""


@dataclass
class Take:
    """One clean take: frames[p] saw pattern p."""

    frames: list[np.ndarray]
    frame_ids: list[int]
    timestamps_ns: list[int]
    filmed: int = 0  # camera frames it took (refused ones and start-up included)
    refused: list[str] = field(default_factory=list)  # why frames or takes were refused, in order

    def note(self) -> str:
        """Empty for a clean first take, else what was refused (the pose was retaken, not saved wrong)."""
        if not self.refused:
            return ""
        why = "; ".join(dict.fromkeys(self.refused))  # unique, in order
        return f"retaken: {len(self.refused)} refused ({why[:160]}); {self.filmed} frames filmed"


def film_triggered(
    camera: Camera,
    projector: Projector,
    trigger: Trigger,
    n: int,
    rate_hz: float,
    check: Callable[[list[np.ndarray]], str | None] | None = None,
    *,
    timeout_s: float = 2.0,
    max_takes: int = MAX_TAKES,
) -> Take:
    """Cycle the n loaded patterns until one whole cycle passes every check of the capture loop
    and then `check` (the pixels of the take).

    The devices must be loaded and not running; they are stopped (not closed) on return.
    """
    # the loop stops the devices but does not close them: the wizard keeps them open
    loop = CaptureLoop(
        camera, projector, trigger, "graycode", n, rate_hz=rate_hz, timeout_s=timeout_s, owns_devices=False
    )
    # The loop's alternation test (a frame must differ from its predecessor) suits two-shot pairs,
    # not Gray code, whose coarse neighbours can look the same in the view; `check` tests the pixels.
    loop.checker.check_alternation = False
    refused: list[str] = []
    budget = (max_takes + 1) * n  # a start-up cycle, then one per take
    dropped = 0
    try:
        for _ in range(budget):
            ev = loop.step()
            if ev.frame is None:
                refused.append(ev.reason)
            if loop.stats.dropped > dropped:
                refused.append(f"{loop.stats.dropped - dropped} frame(s) dropped before frame {ev.raw.frame_id}")
                dropped = loop.stats.dropped
            if ev.frameset is None:
                continue
            frames = [to_rgb(f.image, f.mosaic) for f in ev.frameset.frames]  # (a raw Bayer frame as RGB)
            why = check(frames) if check is not None else None
            if why:
                refused.append(why)
                continue
            fs = ev.frameset.frames
            return Take(frames, [f.frame_id for f in fs], [f.timestamp_ns for f in fs], loop.tick, refused)
    finally:
        loop.close()
    why = "; ".join(dict.fromkeys(refused)) or "no complete cycle"
    raise PoseNotCapturedError(f"camera {camera.name}: no clean take of {n} patterns in {budget} frames ({why[:200]})")


def film_stepped(
    camera: Camera,
    projector: Projector,
    n: int,
    check: Callable[[list[np.ndarray]], str | None],
    *,
    settle: int = 3,
    timeout_s: float = 2.0,
    max_takes: int = MAX_TAKES,
) -> Take:
    """No trigger: show each pattern, skip `settle` frames, keep the next; check the take's pixels.

    The camera must be started; the projector loaded. Returns the first take that passes `check`.
    """
    refused: list[str] = []
    filmed = 0
    for _take in range(max_takes):
        frames: list[np.ndarray] = []
        ids: list[int] = []
        stamps: list[int] = []
        last_id: int | None = None
        broken = ""
        for p in range(n):
            projector.show(p)
            for _ in range(settle + 1):
                f = camera.grab(timeout_s)
                filmed += 1
                if last_id is not None and f.frame_id <= last_id:
                    broken = f"frame {f.frame_id} arrived after frame {last_id}"
                last_id = f.frame_id
            if broken:
                break
            frames.append(to_rgb(f.image, f.mosaic))
            ids.append(f.frame_id)
            stamps.append(f.timestamp_ns)
        why = broken or check(frames)
        if not why:
            return Take(frames, ids, stamps, filmed, refused)
        refused.append(why)
    projector.show(None)
    raise PoseNotCapturedError(
        f"camera {camera.name}: no clean take of {n} patterns in {max_takes} tries ({refused[-1]})"
    )


# ------------------------------------------------------------------------------------ pixel checks


def _grey(img: np.ndarray) -> np.ndarray:
    return img.astype(np.float32).mean(axis=2)


def check_graycode(frames: list[np.ndarray], meta: dict) -> str | None:
    """None if the frames look like the Gray-code sequence in order, else why not.

    Normalised by white and black on the lit surface, a bit frame a and its inverse b satisfy
    a + b ~ 1: a pixel where both are clearly bright or both clearly dark is impossible. A frame
    that saw its partner makes every pixel impossible, one that saw another bit about half of them
    (on the virtual rig: 0 % in a right take, 2-100 % with one late frame, 0 % only when the two
    patterns look the same in the view, which decodes the same). The white frame must be as bright
    as a bit and its inverse together (a late white shows stripes).
    """
    roles = meta["frames"]
    idx = {(r["kind"], r.get("bit"), r.get("inverse")): i for i, r in enumerate(roles)}
    white, black = _grey(frames[idx[("white", None, None)]]), _grey(frames[idx[("black", None, None)]])
    full = 65535.0 if frames[0].dtype == np.uint16 else 255.0
    pairs = [(k, b, i, idx[(k, b, True)]) for (k, b, inv), i in idx.items() if k in ("column", "row") and not inv]
    # the first pair lights every pixel once: the white frame must match it
    total = _grey(frames[pairs[0][2]]) + _grey(frames[pairs[0][3]]) - 2 * black
    on = total > max(0.05 * full, 0.3 * float(np.percentile(total, 99)))
    if on.sum() < 200:
        return "the first Gray-code pair lights nothing the camera sees (projector off or late?)"
    ratio = float(np.median((white - black)[on] / total[on]))
    if ratio < WHITE_RATIO:
        return f"the white frame is {ratio:.2f} of the light a bit and its inverse give (a frame saw another pattern)"
    contrast = white - black
    lit = contrast > max(0.05 * full, 0.3 * float(np.percentile(contrast, 99)))
    c = contrast[lit]
    for kind, bit, i, j in pairs:
        a = (_grey(frames[i])[lit] - black[lit]) / c
        b = (_grey(frames[j])[lit] - black[lit]) / c
        bad = float(np.mean((a - 0.5) * (b - 0.5) > 0.04))  # both >= 0.7 or both <= 0.3
        if bad > IMPOSSIBLE_FRACTION:
            why = f"{100 * bad:.0f} % of pixels equal in frame and inverse"
            return f"{kind} bit {bit}: {why} (a frame saw another pattern)"
    return None


def check_levels(frames: list[np.ndarray], plan: list[tuple[str, int]]) -> str | None:
    """None if each channel's level frames get brighter level by level in that channel, else why not."""
    means = [img.reshape(-1, 3).astype(np.float64).mean(axis=0) for img in frames]
    full = 65535.0 if frames[0].dtype == np.uint16 else 255.0
    last: dict[str, float] = {}
    black = means[0]
    for (ch, level), m in zip(plan, means, strict=True):
        c = "RGB".index(ch)
        if level == 0:
            continue
        prev = last.get(ch, black[c])
        if m[c] <= prev + 1e-4 * full and m[c] < 0.98 * full:
            return f"channel {ch} level {level} is no brighter than the level before (a frame saw another level)"
        last[ch] = m[c]
    return None
