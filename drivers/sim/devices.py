"""Simulated Camera, Projector and Trigger over one VirtualRig, registered as "sim".

Timing model (like a hardware-triggered rig): the trigger ticks at rate_hz (in real time, or
only when `step()` is called in stepped mode, for tests). Each tick exposes one camera frame;
`frame_id` and `trigger_count` are the tick number (1, 2, ...), so dropped frames show as gaps
(after an injected trigger reset, `trigger_count` restarts from 1 while `frame_id` goes on).
The projector's `show(i)` takes effect from the next tick: the frame of tick k shows the
pattern of the last `show` made while the counter was < k. Frames are rendered when grabbed.

Frames leave the camera with `pattern=None`: tagging is the capture loop's job (from its own
record of what it showed, or `SimProjector.flips`). `SimCamera.truth(frame_id)` tells tests
what a frame really saw. Faults can be injected (drop, duplicate, swap, stall, disappear,
late_flip on the camera; reset on the trigger) at given ticks or at random with a probability.
"""

from __future__ import annotations

import bisect
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from core.chroma import chroma_name
from core.errors import DeviceError, InputError
from core.mosaic import mosaic_name
from core.suggest import unknown_name_hint
from drivers.base import CAMERAS, PROJECTORS, TRIGGERS, CameraTimeoutError, Frame, register
from drivers.sim.rig import PreparedPattern, VirtualRig

CAMERA_FAULTS = ("drop", "duplicate", "swap", "stall", "disappear", "late_flip")
TRIGGER_FAULTS = ("reset",)
BUFFER_FRAMES = 8  # like a camera's buffer pool: a consumer further behind loses the oldest frames


@dataclass
class Fault:
    """One injected fault: at given ticks (`at`) or at random per tick (`probability`)."""

    kind: str
    at: tuple[int, ...] = ()
    probability: float = 0.0
    seconds: float = 2.0  # stall length

    def fires(self, tick: int, rng: np.random.Generator) -> bool:
        if tick in self.at:
            return True
        return self.probability > 0 and rng.random() < self.probability


def parse_faults(spec: object, where: str = "sim.faults") -> list[Fault]:
    """[{kind: drop, at: [10, 20]}, {kind: swap, probability: 0.01}, {kind: stall, at: 50, seconds: 2}]."""
    if spec is None:
        return []
    if not isinstance(spec, list):
        raise InputError(f"{where}: must be a list of {{kind, at | probability}}")
    out = []
    for i, f in enumerate(spec):
        if not isinstance(f, dict) or "kind" not in f:
            raise InputError(f"{where}[{i}]: needs 'kind' (one of {', '.join(CAMERA_FAULTS + TRIGGER_FAULTS)})")
        kind = f["kind"]
        if kind not in CAMERA_FAULTS + TRIGGER_FAULTS:
            raise InputError(f"{where}[{i}].kind: {kind!r} is not one of {', '.join(CAMERA_FAULTS + TRIGGER_FAULTS)}")
        at = f.get("at", ())
        at = (at,) if isinstance(at, int) else at
        if not (isinstance(at, list | tuple) and all(isinstance(a, int) and a >= 1 for a in at)):
            raise InputError(f"{where}[{i}].at: must be a tick number >= 1 or a list of them")
        p = f.get("probability", 0.0)
        if not (isinstance(p, int | float) and 0 <= p <= 1):
            raise InputError(f"{where}[{i}].probability: must be 0..1")
        sec = f.get("seconds", 2.0)
        if not (isinstance(sec, int | float) and sec >= 0):
            raise InputError(f"{where}[{i}].seconds: must be >= 0")
        if not at and not p:
            raise InputError(f"{where}[{i}]: give 'at' (ticks) or 'probability'")
        out.append(Fault(kind, tuple(at), float(p), float(sec)))
    return out


class SimBench:
    """The shared state of the three simulated devices: the rig, the clock, the projector's flips."""

    def __init__(
        self,
        rig: VirtualRig,
        stepped: bool = False,
        faults: Sequence[Fault] = (),
        seed: int = 0,
        buffer_frames: int = BUFFER_FRAMES,
    ) -> None:
        if not (isinstance(buffer_frames, int) and buffer_frames >= 1):
            raise InputError(f"sim: buffer_frames must be a whole number >= 1, found {buffer_frames!r}")
        self.rig = rig
        self.buffer_frames = buffer_frames
        self.stepped = stepped
        self.faults = list(faults)
        self.rng = np.random.default_rng(seed + 1000003)
        self.cond = threading.Condition()
        self.rate_hz = 60.0
        self.running = False
        self.t0_ns = 0
        self.ticks = 0  # stepped mode: ticks fired since the bench was made (never reset)
        self.reset_base = 0  # absolute tick at which the trigger box last reset (its counter restarted)
        self._frozen = 0  # real-time counter while stopped
        self.ever_started = False  # a camera whose trigger never started free-runs
        self.epoch = 0  # trigger starts so far: a camera resynchronises to a (re)started trigger
        self.tick_offset = 0  # trigger reset support
        self.patterns: list[PreparedPattern] = []
        self.flips: list[tuple[int, int | None, int]] = []  # (absolute tick at show, index, host ns)

    # -- clock
    def counter(self) -> int:
        with self.cond:
            return self._counter_locked()

    def _counter_locked(self) -> int:
        """What the trigger box reports: ticks since start (or since its last reset)."""
        return self._abs_locked() - self.reset_base

    def visible_id(self, tick: int) -> int:
        """The counter value the box gave absolute tick `tick` (numbering restarts after a reset)."""
        return tick - self.reset_base if tick > self.reset_base else tick

    def _abs_locked(self) -> int:
        if not self.running:
            return self.ticks if self.stepped else self._frozen
        if self.stepped:
            return self.ticks
        return int((time.monotonic_ns() - self.t0_ns) * self.rate_hz // 1_000_000_000) - self.tick_offset

    def tick_time_ns(self, k: int) -> int:
        return self.t0_ns + round((k + self.tick_offset) * 1e9 / self.rate_hz)

    def pattern_at(self, tick: int) -> int | None:
        """Index shown during tick `tick`: the last show made while the tick count was < tick."""
        with self.cond:
            i = bisect.bisect_left(self.flips, tick, key=lambda f: f[0])
            return self.flips[i - 1][1] if i > 0 else None


class SimTrigger:
    """Ticks at rate_hz in real time, or on `step()` when stepped."""

    name = "sim"

    def __init__(self, bench: SimBench) -> None:
        self.bench = bench

    def start(self, rate_hz: float) -> None:
        if not (isinstance(rate_hz, int | float) and 0 < rate_hz <= 10000):
            raise InputError(f"sim trigger: rate {rate_hz!r} Hz must be in (0, 10000]")
        b = self.bench
        with b.cond:
            b.rate_hz = float(rate_hz)
            b.t0_ns = time.monotonic_ns()
            b.tick_offset = -b.ticks if b.stepped else 0
            if not b.stepped:
                # real-time ticks count from 0 again: what is on screen stays, as shown "before tick 1"
                b.flips = [(0, b.flips[-1][1], b.flips[-1][2])] if b.flips else []
                b.reset_base = 0
            b.running = True
            b.ever_started = True
            b.epoch += 1
            b.cond.notify_all()

    def stop(self) -> None:
        b = self.bench
        with b.cond:
            if b.running:
                b._frozen = b._counter_locked()
                if b.stepped:
                    b._frozen = b.ticks
            b.running = False
            b.cond.notify_all()

    def counter(self) -> int:
        return self.bench.counter()

    def step(self, n: int = 1) -> int:
        """Stepped mode: fire n ticks now; returns the counter."""
        b = self.bench
        if not b.stepped:
            raise DeviceError("sim trigger: step() needs stepped mode (sim: stepped: true)")
        with b.cond:
            if not b.running:
                raise DeviceError("sim trigger: not started (call start(rate_hz) first)")
            for _ in range(n):
                b.ticks += 1
                for f in b.faults:
                    if f.kind == "reset" and f.fires(b.ticks, b.rng):
                        b.reset_base = b.ticks  # a trigger box that reboots: its counter starts again at 0
            b.cond.notify_all()
            return b._counter_locked()

    def close(self) -> None:
        self.stop()


class SimProjector:
    """Holds the prepared patterns; `show(i)` applies from the next trigger tick."""

    name = "sim"
    thread_bound = False  # no window: any thread may call it

    def __init__(self, bench: SimBench) -> None:
        self.bench = bench
        self.size = bench.rig.projector_size
        self._closed = False
        self.stop_requested = False  # nobody closes a window that is not there; request_stop sets it

    def load(self, images: Sequence[np.ndarray]) -> None:
        prepared = [self.bench.rig.prepare(img) for img in images]  # checks each size
        with self.bench.cond:
            self.bench.patterns = prepared

    def show(self, index: int | None) -> int | None:
        b = self.bench
        if self._closed:
            raise DeviceError("sim projector: closed")
        if index is not None and not 0 <= index < len(b.patterns):
            raise InputError(f"sim projector: pattern {index} not loaded ({len(b.patterns)} loaded)")
        with b.cond:
            b.flips.append((b._abs_locked(), index, time.monotonic_ns()))
            if len(b.flips) > 4096:  # keep the history bounded; old entries are never asked for
                del b.flips[: len(b.flips) - 2048]
        return None  # the flip time is the trigger tick's, which the loop knows

    def poll(self) -> bool:
        return not self.stop_requested

    def request_stop(self) -> None:
        self.stop_requested = True

    @property
    def flips(self) -> list[tuple[int, int | None, int]]:
        """(tick count when shown, pattern index, host ns): the index applies from the next tick on.

        Tick counts here never restart (they equal the trigger counter unless the box was reset).
        """
        with self.bench.cond:
            return list(self.bench.flips)

    def close(self) -> None:
        self._closed = True


class SimCamera:
    """Renders one frame per trigger tick with the pattern shown at that tick."""

    name = "sim"
    device = "sim"

    def __init__(self, bench: SimBench) -> None:
        self.bench = bench
        self._started = False
        self._gone = False
        self._next_tick = 1
        self._epoch = 0
        self._pending: deque[Frame] = deque()
        self._truth: dict[int, int | None] = {}
        self.dropped = 0  # frames lost to a slow consumer (buffer overrun), not injected faults

    def start(self) -> None:
        if self._gone:
            raise DeviceError("sim camera: device disappeared (reopen it)")
        self._started = True
        with self.bench.cond:
            self._next_tick = self.bench._abs_locked() + 1
            self._epoch = self.bench.epoch

    def stop(self) -> None:
        self._started = False
        self._pending.clear()

    def close(self) -> None:
        self.stop()

    def truth(self, frame_id: int) -> int | None:
        """The pattern index the frame with this id really saw (tests only)."""
        return self._truth.get(frame_id)

    def inject(self, kind: str, at: int | Sequence[int] = (), probability: float = 0.0, seconds: float = 2.0) -> None:
        self.bench.faults.extend(
            parse_faults([{"kind": kind, "at": at, "probability": probability, "seconds": seconds}])
        )

    def _render(self, tick: int, pattern_tick: int) -> Frame:
        b = self.bench
        free_run = not b.ever_started and not b.stepped
        idx = b.pattern_at(pattern_tick)
        light = b.rig.black() if idx is None else b.patterns[idx]
        image = b.rig.render(light)
        self._truth[tick] = idx
        if len(self._truth) > 8192:
            for k in sorted(self._truth)[:4096]:
                del self._truth[k]
        if free_run:  # no trigger: host time, no trigger count
            return Frame(
                image=image, frame_id=tick, timestamp_ns=time.monotonic_ns(), pattern=None, mosaic=b.rig.mosaic
            )
        # frame_id: the camera's own exposure counter; trigger_count: the box's (restarts after a reset)
        count = b.visible_id(tick)
        ts = b.tick_time_ns(tick)
        return Frame(
            image=image, frame_id=tick, timestamp_ns=ts, pattern=None, trigger_count=count, mosaic=b.rig.mosaic
        )

    def grab(self, timeout_s: float = 1.0) -> Frame:
        b = self.bench
        if self._gone:
            raise DeviceError("sim camera: device disappeared (unplugged?); check the connection and reopen")
        if not self._started:
            raise DeviceError("sim camera: not started (call start() first)")
        if self._pending:
            return self._pending.popleft()
        deadline = time.monotonic() + timeout_s
        with b.cond:
            if self._epoch != b.epoch:  # the trigger (re)started since: its first tick is next
                self._epoch = b.epoch
                self._next_tick = b._abs_locked() + 1
            while True:
                if not b.ever_started and not b.stepped:
                    # free-running, no trigger ever started: expose now with what is shown now
                    # (once a trigger has run, a stopped trigger means no frames: a timeout)
                    tick = self._next_tick
                    break
                count = b._abs_locked()
                if count >= self._next_tick:
                    if count - self._next_tick >= b.buffer_frames:
                        skip = count - b.buffer_frames + 1 - self._next_tick
                        self.dropped += skip
                        self._next_tick += skip
                    tick = self._next_tick
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    raise CameraTimeoutError(f"sim camera: no frame within {timeout_s:.3f} s (is the trigger running?)")
                if b.stepped:
                    b.cond.wait(left)
                else:
                    wait = (b.tick_time_ns(self._next_tick) - time.monotonic_ns()) / 1e9
                    b.cond.wait(min(left, max(wait, 0.0005)))
            self._next_tick = tick + 1
        return self._deliver(tick, timeout_s)

    def _deliver(self, tick: int, timeout_s: float) -> Frame:
        b = self.bench
        for f in b.faults:
            if f.kind == "reset" or not f.fires(tick, b.rng):
                continue
            if f.kind == "disappear":
                self._gone = True
                self._started = False
                raise DeviceError("sim camera: device disappeared (unplugged?); check the connection and reopen")
            if f.kind == "stall":
                time.sleep(f.seconds if not b.stepped else 0)
                if f.seconds > timeout_s:
                    raise CameraTimeoutError(f"sim camera: no frame within {timeout_s:.3f} s (stalled)")
            if f.kind == "drop":
                return self.grab(timeout_s)
            if f.kind == "duplicate":
                frame = self._render(tick, tick)
                self._pending.append(frame)
                return frame
            if f.kind == "swap":
                # deliver tick+1 before tick (needs the next tick to have happened)
                with b.cond:
                    self._next_tick = tick + 2
                later = self._wait_tick(tick + 1, timeout_s)
                first = self._render(later, later) if later else None
                frame = self._render(tick, tick)
                if first is None:
                    return frame
                self._pending.append(frame)
                return first
            if f.kind == "late_flip":
                # the projector flipped a frame late: this exposure still saw the previous pattern
                return self._render(tick, tick - 1)
        return self._render(tick, tick)

    def _wait_tick(self, tick: int, timeout_s: float) -> int | None:
        b = self.bench
        deadline = time.monotonic() + timeout_s
        with b.cond:
            while b._abs_locked() < tick:
                left = deadline - time.monotonic()
                if left <= 0 or not b.running:
                    return None
                b.cond.wait(min(left, 0.002) if not b.stepped else left)
        return tick


class SimDevices(NamedTuple):
    """`camera, projector, trigger = make_sim_rig(config)`; `.rig` and `.bench` are shared by all three."""

    camera: SimCamera
    projector: SimProjector
    trigger: SimTrigger

    @property
    def bench(self) -> SimBench:
        return self.camera.bench

    @property
    def rig(self) -> VirtualRig:
        return self.camera.bench.rig


# ----------------------------------------------------------------------------- construction

SIM_KEYS = (
    "scene",
    "camera_size",
    "projector_size",
    "ideal",
    "seed",
    "stepped",
    "bit_depth",
    "bayer",
    "chroma",
    "effects",
    "faults",
    "buffer_frames",
)


def make_bench(
    scene: str = "face",
    ideal: bool = False,
    stepped: bool = False,
    faults: object = None,
    seed: int = 0,
    buffer_frames: int = BUFFER_FRAMES,
    **rig_options: object,
) -> SimBench:
    """A rig over a preset plus the devices' shared clock; rig_options as VirtualRig.from_preset."""
    parsed = parse_faults(faults)  # before the (slow) rig, so a bad fault list fails at once
    rig = VirtualRig.from_preset(scene, ideal=ideal, seed=seed, **rig_options)
    return SimBench(rig, stepped=stepped, faults=parsed, seed=seed, buffer_frames=buffer_frames)


def devices_from_bench(bench: SimBench) -> SimDevices:
    return SimDevices(SimCamera(bench), SimProjector(bench), SimTrigger(bench))


def make_sim_rig(config: object) -> SimDevices:
    """Build the simulated camera, projector and trigger from a Config's `sim:` section.

    Keys: scene, camera_size, projector_size (as before), and optionally ideal, seed, stepped,
    bit_depth, buffer_frames, effects (a mapping of RigOptions overrides) and faults (see
    parse_faults). Each call builds a new rig; the "sim" registry factories share one per config.
    """
    return devices_from_bench(bench_from_config(config))


def bench_from_config(config: object) -> SimBench:
    """A new SimBench from a Config's `sim:` section (errors name the file and key)."""
    sim = config.section("sim")
    where = f"{config.path}"
    for key in sim:
        if key not in SIM_KEYS:
            raise InputError(f"{where}: key 'sim.{key}' is unknown{unknown_name_hint(str(key), SIM_KEYS, 'sim.')}")
    opts: dict = {}
    for key in ("camera_size", "projector_size"):
        if key in sim:
            v = sim[key]
            if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) and x > 0 for x in v)):
                raise InputError(f"{where}: key 'sim.{key}' must be [w, h] positive whole numbers, found {v!r}")
            opts[key] = (v[0], v[1])
    if "bit_depth" in sim:
        opts["bit_depth"] = sim["bit_depth"]
    if "bayer" in sim:
        opts["bayer"] = mosaic_name(sim["bayer"], f"{where}: key 'sim.bayer'")
    if "chroma" in sim:
        opts["chroma"] = chroma_name(sim["chroma"], f"{where}: key 'sim.chroma'")
    effects = sim.get("effects") or {}
    if not isinstance(effects, dict):
        raise InputError(f"{where}: key 'sim.effects' must be a mapping")
    opts.update(effects)
    scene = sim.get("scene", "face")
    if not isinstance(scene, str):
        raise InputError(f"{where}: key 'sim.scene' must be a preset name (see `slscan sim scenes`)")
    seed = sim.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise InputError(f"{where}: key 'sim.seed' must be a whole number, 0 or more")
    bench = make_bench(
        scene=scene,
        ideal=bool(sim.get("ideal", False)),
        stepped=bool(sim.get("stepped", False)),
        faults=sim.get("faults"),
        seed=seed,
        buffer_frames=sim.get("buffer_frames", BUFFER_FRAMES),
        **opts,
    )
    return bench


# Registry factories: devices made separately through the registry share one bench (one rig):
# pass bench=, or config= (the `sim:` section of that Config), or make_bench keyword options;
# the same config / options give the same bench, so "sim" for all three is a consistent set.
_SHARED: dict[tuple, SimBench] = {}
_SHARED_LOCK = threading.Lock()


def shared_bench(bench: SimBench | None = None, config: object = None, **options: object) -> SimBench:
    if bench is not None:
        return bench
    if config is not None:
        key: tuple = ("config", str(config.path), repr(config.data.get("sim")))
    else:
        key = tuple(sorted((k, repr(v)) for k, v in options.items()))
    with _SHARED_LOCK:
        if key not in _SHARED:
            _SHARED[key] = bench_from_config(config) if config is not None else make_bench(**options)
        return _SHARED[key]


def forget_shared_benches() -> None:
    """Drop the registry's shared benches (a new session starts from fresh rigs)."""
    with _SHARED_LOCK:
        _SHARED.clear()


@register(CAMERAS, "sim")
def _sim_camera(bench: SimBench | None = None, config: object = None, **options: object) -> SimCamera:
    return SimCamera(shared_bench(bench, config, **options))


@register(PROJECTORS, "sim")
def _sim_projector(bench: SimBench | None = None, config: object = None, **options: object) -> SimProjector:
    return SimProjector(shared_bench(bench, config, **options))


@register(TRIGGERS, "sim")
def _sim_trigger(bench: SimBench | None = None, config: object = None, **options: object) -> SimTrigger:
    return SimTrigger(shared_bench(bench, config, **options))


__all__ = [
    "CAMERA_FAULTS",
    "Fault",
    "SimBench",
    "SimCamera",
    "SimDevices",
    "SimProjector",
    "SimTrigger",
    "bench_from_config",
    "forget_shared_benches",
    "make_bench",
    "make_sim_rig",
    "parse_faults",
]
