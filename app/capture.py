"""The capture loop: pace the rig, tag every camera frame with the pattern it saw, check the tag,
and group checked frames into frame sets (sliding pairs for two-shot).

A swapped two-shot pair inverts every sign and decodes to wrong but plausible stripes,
so a tag is never assumed. Every frame is placed on the loop's own schedule (its *tick*:
the n-th projector refresh since start) from the camera's counters, and its tag is the pattern the
flip log says the projector showed at that tick. The frame is refused (counted, never paired) when

- its tick cannot be established (no flip recorded there, counters not yet anchored after a reset),
- the flip at its tick was late (the camera may have seen the previous pattern),
- a tag reported by the device (trigger-box phase marker, a camera line input) disagrees,
- its frame_id repeats or goes back (a duplicate or a swap in delivery), or its image is a byte-for-
  byte repeat of the previous frame (a duplicated buffer under a new id),
- its pixels repeat the previous pattern instead of alternating (a flip that came late and left
  no trace in any counter: `check_alternation`).

A frame_id gap (a dropped frame) only breaks the current pair. What no check can see is a
projector late on *every* refresh (the whole stream one pattern behind, alternating perfectly):
that needs the trigger box's phase marker as a device tag, or the flip times. The pure part (`FrameChecker`) has
no devices and no clock, so the pairing rules are unit-tested directly; `CaptureLoop` drives the
devices. Grouping uses `app.framesets.group_frame_sets` on the last frames, so the live session and
`slscan decode` follow one rule.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from app.framesets import group_frame_sets
from app.schemes import get_scheme
from drivers.base import Camera, Frame, PeekableTrigger, Projector, Trigger


@dataclass(frozen=True)
class Shown:
    """One flip-log entry: at `tick` the projector was asked to show `pattern`, and flipped at flip_ns."""

    tick: int
    pattern: int | None
    flip_ns: int
    late: bool = False  # the flip missed its refresh: the frame of this tick is not trusted


class FlipLog:
    """Bounded record tick -> Shown (the newest `maxlen` ticks)."""

    def __init__(self, maxlen: int = 4096) -> None:
        self._entries: dict[int, Shown] = {}
        self._order: deque[int] = deque()
        self.maxlen = maxlen

    def record(self, shown: Shown) -> None:
        if shown.tick not in self._entries:
            self._order.append(shown.tick)
        self._entries[shown.tick] = shown
        while len(self._order) > self.maxlen:
            self._entries.pop(self._order.popleft(), None)

    def clear(self) -> None:
        self._entries.clear()
        self._order.clear()

    def get(self, tick: int) -> Shown | None:
        return self._entries.get(tick)

    def entries(self) -> list[Shown]:
        """Every entry kept, in the order the ticks were first recorded."""
        return [self._entries[t] for t in self._order]


@dataclass
class CaptureStats:
    """Counters the status line and the bench print; every refused frame is counted once."""

    frames: int = 0  # frames received from the camera
    tagged: int = 0  # frames whose tag passed every check
    dropped: int = 0  # frames missing from the camera stream (frame_id gaps)
    duplicates: int = 0  # a frame_id or an image received twice
    out_of_order: int = 0  # frame_id went back (frames swapped in delivery)
    mistagged: int = 0  # tag evidence disagreed: device tag vs flip log, or a late flip
    untracked: int = 0  # no flip recorded at the frame's tick, or counters not anchored
    resyncs: int = 0  # a counter reset (trigger box reboot, camera restart) re-anchored the schedule
    sets: int = 0  # complete frame sets handed on
    textures: int = 0  # white-light texture frames tagged (in no set; also counted in tagged and confirmed)
    confirmed: int = 0  # tagged frames whose tag the pixel check confirmed (all tagged ones without it)

    @property
    def refused(self) -> int:
        """Frames that would have made a mispaired set had the tag been assumed."""
        return self.duplicates + self.out_of_order + self.mistagged + self.untracked

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["refused"] = self.refused
        return d


@dataclass(frozen=True)
class FrameSet:
    """The frames of one pattern cycle, in pattern order (frames[p] saw pattern p)."""

    frames: tuple[Frame, ...]
    reversed_order: bool = False  # two-shot: the pattern-1 frame came first in time
    arrival_ns: int = 0  # host time the newest frame of the set arrived (for latency)
    # two-shot: the checked frame just before the set (it saw the newest frame's pattern), for motion detection
    previous: Frame | None = None

    @property
    def frame_ids(self) -> tuple[int, ...]:
        return tuple(f.frame_id for f in self.frames)

    @property
    def newest(self) -> Frame:
        return max(self.frames, key=lambda f: f.frame_id)

    @property
    def newest_index(self) -> int:
        """The pattern index of the frame taken last."""
        return 0 if self.reversed_order else len(self.frames) - 1


@dataclass
class _Accepted:
    frame: Frame
    tick: int
    sample: np.ndarray | None = None  # sparse pixels for the alternation check
    verified: bool = True  # passed the alternation check (or it is off)
    confirmed: bool = False  # its tag is certain: handed to the recorder


# A two-shot frame must differ from its predecessor (the inverse pattern) at least this many times
# more than from the frame before that (the same pattern): a flip that came late repeats a pattern.
ALTERNATION_RATIO = 2.0
# A texture frame (white) must be at least this much brighter on average than the pattern frame before it.
TEXTURE_BRIGHTER = 1.2
# A trigger count at most this far behind the last one (and past the first few) is a late delivery.
SWAP_WINDOW = 8
# The capture loop asks the trigger box for its count at least this often (between, it peeks at events).
QUERY_INTERVAL_NS = 100_000_000


@dataclass
class FrameChecker:
    """Tag, check and pair frames (pure: no devices, no clock).

    scheme, n_patterns: of the pattern set; the projector shows pattern `order[t % len(order)]`
    at tick t (the loop records that in `flips`). Frames are placed on ticks by
    `trigger_count` (the trigger box's count of this exposure, 1 = first trigger after the anchor)
    when the camera reports it, else by frame_id relative to the first frame.
    """

    scheme: str
    n_patterns: int
    flips: FlipLog = field(default_factory=FlipLog)
    sliding: bool = True
    check_content: bool = True
    # Replay: the frames carry tags checked when they were recorded (no projector, no flip log).
    device_tags: bool = False
    # Check from the pixels that each frame differs from its predecessor more than from the frame
    # of the same pattern one cycle earlier (catches a late flip that left no trace in any counter).
    # A set then needs its frames' predecessors of one cycle before: sets start one cycle later.
    # Suits patterns that all look different in the camera (two-shot's pair); not Gray code, whose
    # coarse bits can look alike on a small board (the calibration wizard checks its takes by pixels).
    check_alternation: bool = False
    # The tag of white-light texture frames (app/texture.py: n_patterns, one past the patterns), None = none shown.
    # A texture frame passes the same tag checks, is handed on (and recorded), and breaks the pair: it is in no set.
    texture_pattern: int | None = None
    stats: CaptureStats = field(default_factory=CaptureStats)

    def __post_init__(self) -> None:
        # (two-shot: a pair and the frame before it)
        self._history: deque[_Accepted] = deque(maxlen=max(3, self.n_patterns))
        self._refs: dict[int, tuple[int, np.ndarray]] = {}  # pattern -> (tick, sample) of its last frame
        self._trigger_base: int | None = 0  # tick of trigger count 1; None = waiting for an anchor
        self._id_base: int | None = None  # tick = frame_id - _id_base when no trigger count
        self._last_trigger: int | None = None
        self._last_id: int | None = None
        self._last_sample: bytes | None = None
        self._last_texture_tick: int | None = None
        self.last_reason: str = ""
        self.confirmed: list[Frame] = []

    # ------------------------------------------------------------------ anchoring

    def anchor_trigger(self, tick_of_first_trigger: int) -> None:
        """The trigger was (re)started so that its count 1 fires at this tick.

        The last count seen is kept: the first frame of the new count goes back, so it is refused
        (one frame) — and a count that restarts again before the next anchor is caught the same way.
        """
        self._trigger_base = tick_of_first_trigger

    def anchor_frame_id(self, frame_id: int, tick: int) -> None:
        """Camera frame `frame_id` was exposed at `tick` (used when frames carry no trigger count)."""
        self._id_base = frame_id - tick

    # ------------------------------------------------------------------ per frame

    def _refuse(self, counter: str, reason: str, *, break_pair: bool = True) -> tuple[None, None]:
        setattr(self.stats, counter, getattr(self.stats, counter) + 1)
        self.last_reason = reason
        if break_pair:
            self._history.clear()
        return None, None

    def tick_of(self, frame: Frame) -> int | None:
        if self.device_tags:
            return frame.frame_id
        if frame.trigger_count is not None:
            if self._trigger_base is None:
                return None
            return self._trigger_base + frame.trigger_count - 1
        if self._id_base is None:
            return None
        return frame.frame_id - self._id_base

    def push(self, frame: Frame, arrival_ns: int = 0) -> tuple[Frame | None, FrameSet | None]:
        """Check one frame; returns (the frame with its tag, or None if refused; a completed set or None)."""
        st = self.stats
        st.frames += 1
        self.confirmed = []  # frames whose tags this push confirmed, in capture order (for the recorder)
        # Counter resets: the trigger box rebooted (count back to <= last) or the camera restarted.
        # A count a little behind a large last count is a frame delivered late (a swap), not a reset.
        if frame.trigger_count is not None and self._last_trigger is not None:
            back = self._last_trigger - frame.trigger_count
            if back == 0 and frame.frame_id == self._last_id:
                return self._refuse("duplicates", f"frame {frame.frame_id} received twice", break_pair=False)
            if back >= 0 and (back > SWAP_WINDOW or frame.trigger_count <= SWAP_WINDOW):
                # The box reset: this frame belongs to a schedule the loop has not re-made yet.
                self._last_trigger = frame.trigger_count
                self._last_id = frame.frame_id
                return self._refuse("untracked", "trigger counter went back (box reset?)")
        prev_id = self._last_id
        if prev_id is not None:
            if frame.frame_id == prev_id:
                return self._refuse("duplicates", f"frame {frame.frame_id} received twice", break_pair=False)
            if frame.frame_id < prev_id:
                if frame.trigger_count is None and prev_id - frame.frame_id > 64:
                    # The camera restarted its counter: re-anchor on the next frame of a known tick.
                    st.resyncs += 1
                    self._id_base = None
                    self._last_id = frame.frame_id
                    return self._refuse("untracked", "camera frame counter restarted: waiting to re-anchor")
                return self._refuse("out_of_order", f"frame {frame.frame_id} arrived after frame {prev_id}")
            if frame.frame_id > prev_id + 1:
                st.dropped += frame.frame_id - prev_id - 1  # frames the camera never delivered
                self._history.clear()
        self._last_id = frame.frame_id
        if frame.trigger_count is not None:
            self._last_trigger = frame.trigger_count
        if self.check_content:
            sample = _content_sample(frame.image)
            if sample == self._last_sample:
                return self._refuse("duplicates", f"frame {frame.frame_id} repeats the previous image")
            self._last_sample = sample
        tick = self.tick_of(frame)
        if tick is None:
            return self._refuse("untracked", f"frame {frame.frame_id}: schedule not anchored")
        shown = Shown(tick, frame.pattern, frame.timestamp_ns) if self.device_tags else self.flips.get(tick)
        if shown is None or shown.pattern is None:
            return self._refuse("untracked", f"frame {frame.frame_id}: no pattern recorded at tick {tick}")
        if shown.late:
            return self._refuse("mistagged", f"frame {frame.frame_id}: the flip at tick {tick} was late")
        texture = self.texture_pattern is not None and shown.pattern == self.texture_pattern
        if not (0 <= shown.pattern < self.n_patterns or texture):
            return self._refuse("mistagged", f"frame {frame.frame_id}: tag {shown.pattern} outside the scheme")
        if frame.pattern is not None and frame.pattern != shown.pattern:
            return self._refuse(
                "mistagged",
                f"frame {frame.frame_id}: device tag {frame.pattern} != pattern {shown.pattern} shown at tick {tick}",
            )
        tagged = dataclasses.replace(frame, pattern=shown.pattern)
        st.tagged += 1
        if self._history:
            last = self._history[-1]
            if frame.frame_id != last.frame.frame_id + 1 or tick != last.tick + 1:
                # ids consecutive but ticks not: the two counters disagree; trust neither for a pair.
                self._history.clear()
        if texture:
            # Its tag is the flip log's, checked above; its pixels must be brighter than the pattern before it (white
            # lights every channel a pattern lights). It stays in the history as the next frame's predecessor: a
            # late flip after it leaves that frame white, which the pixel check sees. It is in no set:
            # group_frame_sets never pairs its tag.
            acc = _Accepted(tagged, tick, confirmed=True)
            if self.check_alternation:
                acc.sample = _alternation_sample(frame.image)
                h = self._history
                if h and h[-1].tick == tick - 1 and h[-1].sample is not None:
                    if float(np.mean(acc.sample)) < TEXTURE_BRIGHTER * float(np.mean(h[-1].sample)):
                        st.tagged -= 1
                        return self._refuse(
                            "mistagged", f"frame {frame.frame_id}: a texture frame no brighter than a pattern (late?)"
                        )
            st.textures += 1
            st.confirmed += 1
            self.confirmed.append(tagged)
            self._last_texture_tick = tick
            self._history.append(acc)
            return tagged, None
        acc = _Accepted(tagged, tick)
        if self.check_alternation:
            acc.sample = _alternation_sample(frame.image)
            acc.verified = False
            h = self._history
            ref = self._refs.get(shown.pattern)
            # (the frame of this pattern one cycle back; two cycles back where a texture frame took that tick: an
            # older reference can only refuse more, never pass a frame that repeats its predecessor)
            n = self.n_patterns
            cycle_back = ref is not None and (
                ref[0] == tick - n or (ref[0] == tick - 2 * n and self._last_texture_tick == tick - n)
            )
            if h and h[-1].tick == tick - 1 and cycle_back:
                d_prev = float(np.mean(np.abs(acc.sample - h[-1].sample)))  # type: ignore[operator]
                d_same = float(np.mean(np.abs(acc.sample - ref[1])))
                if d_prev <= ALTERNATION_RATIO * d_same:
                    st.tagged -= 1
                    return self._refuse(
                        "mistagged", f"frame {frame.frame_id}: its pixels repeat a pattern (a flip came late?)"
                    )
                acc.verified = True
                # Two patterns: the frame before differs from this one, which matches the frame of
                # its pattern one cycle back, so the frame before holds the other pattern: confirmed.
                if self.n_patterns == 2 and not h[-1].confirmed:
                    h[-1].confirmed = True
                    self.confirmed.append(h[-1].frame)
            self._refs[shown.pattern] = (tick, acc.sample)
        acc.confirmed = acc.verified
        if acc.confirmed:
            self.confirmed.append(tagged)
        st.confirmed += len(self.confirmed)
        self._history.append(acc)
        return tagged, self._complete_set(arrival_ns)

    def _complete_set(self, arrival_ns: int) -> FrameSet | None:
        kind = get_scheme(self.scheme)
        need = kind.frames_per_set(self.n_patterns)
        if len(self._history) < need:
            return None
        # a two-shot pair takes the checked frame before it too: group_frame_sets says whether it is the pair's
        # previous frame (consecutive, and of the newest frame's pattern), for motion detection
        extra = 1 if need == 2 and len(self._history) > need and self._history[-need - 1].verified else 0
        window = list(self._history)[-(need + extra) :]
        if not all(a.verified for a in window):
            return None
        # Ticks stand in for frame ids: the checks above made both consecutive together.
        tags = [(a.tick, int(a.frame.pattern)) for a in window]  # type: ignore[arg-type]
        sets, _ = group_frame_sets(tags, self.scheme, self.n_patterns, sliding=True)
        if not sets or sets[-1].first != extra:
            return None
        fs = sets[-1]
        frames = tuple(window[i].frame for i in fs.indices)
        previous = window[fs.previous].frame if fs.previous is not None else None
        if not self.sliding or kind.disjoint_sets:
            self._history.clear()
        self.stats.sets += 1
        return FrameSet(frames, fs.reversed_order, arrival_ns, previous)


def _alternation_sample(image: np.ndarray) -> np.ndarray:
    """Every 8th pixel each way, as float32: enough to tell a pattern from its inverse."""
    return image[4::8, 4::8].astype(np.float32)


def _content_sample(image: np.ndarray) -> bytes:
    """A few sparse rows of the image: identical bytes mean the same buffer delivered twice (sensors are noisy)."""
    h = image.shape[0]
    return image[h // 7 :: max(1, h // 5)].tobytes()


# ------------------------------------------------------------------------------------- the loop


def pattern_order(scheme: str, n_patterns: int) -> list[int]:
    """Projection order: two-shot alternates 0, 1, 0, 1 (so sliding pairs give a set per frame)."""
    return get_scheme(scheme).frame_order(n_patterns)


@dataclass
class LoopEvent:
    """What one step of the loop produced."""

    frame: Frame | None  # tagged frame (None if refused)
    raw: Frame  # the frame as the camera gave it
    confirmed: list[Frame]  # tagged frames (this one, or the one before) whose tag is now certain
    frameset: FrameSet | None
    arrival_ns: int
    reason: str = ""  # why the frame was refused
    texture: Frame | None = None  # this step's frame, tagged, when it is a white-light texture frame


class CaptureLoop:
    """Drive projector + trigger + camera, tag, check and pair every frame.

    With a trigger (the trigger box, or the virtual rig's), the trigger paces: each step reads the
    trigger counter c, shows the pattern of tick c + 1 (`order[c % n]`: phase 0 = pattern 0, as the
    box marks it), reads the counter again and logs the flip at tick c + 1 — or as late if a
    trigger fired meanwhile (the camera may have seen either pattern) — then grabs the next frame,
    which blocks until the camera has one. A frame is placed on its tick by its trigger count.
    A show made while the counter reads c takes effect from tick c + 1 (the sim rig's timing, and
    a projector whose flip precedes the vsync edge that fires the box).

    Without a trigger, the loop paces itself at `rate_hz` (or the projector's vsync blocks in
    `show`): show, then grab; ticks are the camera's frame ids, anchored on the first frame.
    With no projector (replay), the frames' recorded tags are used and checked for pairing.
    All device calls happen on the thread that calls `step` (pyglet windows require it).
    """

    def __init__(
        self,
        camera: Camera,
        projector: Projector | None,
        trigger: Trigger | None,
        scheme: str,
        n_patterns: int,
        *,
        rate_hz: float = 60.0,
        timeout_s: float = 2.0,
        pace: bool = True,
        projector_thread: bool | None = None,
        clock: Callable[[], int] = time.monotonic_ns,
        owns_devices: bool = True,
        texture_every: int | None = None,
    ) -> None:
        """texture_every: show the white-light texture frame (projector image n_patterns, app/texture.py, which the
        projector must have loaded) at every tick that is a multiple of it; request_texture() asks for one now. Replay
        (no projector) takes the texture frames a dump recorded."""
        self.camera, self.projector, self.trigger = camera, projector, trigger
        self.owns_devices = owns_devices  # False: close() stops the devices but leaves them open
        # With a trigger, flips follow the trigger counter on their own thread, so a slow grab or
        # decode never leaves a tick without its pattern. Not for a projector whose window belongs
        # to the thread that opened it (Projector.thread_bound); there the loop shows inline, unless
        # it is wrapped to be callable from any thread (app/owner_thread.py).
        if projector_thread is None:
            thread_bound = projector is not None and projector.thread_bound
            projector_thread = projector is not None and trigger is not None and not thread_bound
        self._use_thread = bool(projector_thread) and projector is not None and trigger is not None
        self._proj_stop = threading.Event()
        self._proj_thread: threading.Thread | None = None
        self._proj_error: BaseException | None = None
        self.projector_cpu_s = 0.0  # CPU seconds the projector thread used (for the bench)
        self.scheme = scheme
        self.order = pattern_order(scheme, n_patterns)
        self.rate_hz = rate_hz
        self.period_ns = int(1e9 / rate_hz)
        self.timeout_s = timeout_s
        self.pace = pace
        self.clock = clock
        self.flips = FlipLog()
        # No projector (replay): the frames carry their recorded tags.
        self.checker = FrameChecker(
            scheme,
            n_patterns,
            self.flips,
            device_tags=projector is None,
            check_alternation=projector is not None and get_scheme(scheme).alternates,
            texture_pattern=n_patterns,
        )
        if texture_every is not None and texture_every < 2:
            raise ValueError(f"texture_every {texture_every}: must be at least 2 (or None)")
        self.texture_every = texture_every
        self._texture_requested = False  # (set by any thread, taken by the one that shows)
        self.tick = 0  # steps made
        self._deadline = 0
        self._started = False
        self._count = 0  # last trigger count read
        self._last_query_ns = 0  # when the trigger box was last asked for its count (not peeked)

    @property
    def stats(self) -> CaptureStats:
        return self.checker.stats

    def request_texture(self) -> None:
        """Show the texture frame at the next tick the projector is given (snapshot, the view's t key)."""
        self._texture_requested = True

    def _pattern_at(self, tick: int, order_index: int) -> int:
        """The image to show at a tick: the texture frame when it is due there, else the pattern order's."""
        if self.texture_every is not None and tick > 0 and tick % self.texture_every == 0:
            return self.checker.n_patterns
        if self._texture_requested:
            self._texture_requested = False
            return self.checker.n_patterns
        return self.order[order_index % len(self.order)]

    @property
    def stop_requested(self) -> bool:
        """The operator closed the projector window (or pressed Esc/q in it): end the session cleanly."""
        return self.projector is not None and bool(self.projector.stop_requested)

    def start(self) -> None:
        self.camera.start()
        if self.trigger is not None:
            self.trigger.start(self.rate_hz)
            self._count = 0
        self.checker.anchor_trigger(1)  # trigger count k is tick k
        if self.trigger is not None and self.projector is not None:
            # A camera that reports no trigger count: its frame counter, started before the
            # trigger, counts the triggers (GenICam frame ids count from 1 per start).
            self.checker.anchor_frame_id(0, 0)
        self._deadline = self.clock()
        self._started = True
        if self._use_thread:
            self._proj_stop.clear()
            self._proj_thread = threading.Thread(target=self._projector_run, name="projector", daemon=True)
            self._proj_thread.start()

    def _projector_run(self) -> None:
        """Show the next pattern as soon as the trigger counter moves.

        The counter is polled every millisecond, but only from 3/4 of a period after the last
        move: ~4 reads per frame instead of ~16 (measured: the thread's CPU 0.85 -> 0.2 ms a frame).
        """
        quiet_ns = int(0.75 * self.period_ns)
        cpu0 = time.thread_time()
        try:
            self._show_triggered()
            moved_ns = time.monotonic_ns()
            # The quiet time counts from when the move was seen, not from the end of the show:
            # a slow show (a window flip, ~6 ms on Xvfb) must not push the next poll past a tick.
            while not self._proj_stop.wait(max(0, moved_ns + quiet_ns - time.monotonic_ns()) / 1e9):
                while not self._proj_stop.is_set() and self._read_counter() == self._count:
                    time.sleep(0.001)
                moved_ns = time.monotonic_ns()
                if not self._proj_stop.is_set():
                    self._show_triggered()
        except BaseException as exc:  # handed to the acquisition thread at its next step
            self._proj_error = exc
        finally:
            self.projector_cpu_s += time.thread_time() - cpu0

    def step(self) -> LoopEvent:
        """One frame: show, grab, check. Raises CameraTimeoutError if the camera stops sending."""
        if not self._started:
            self.start()
        if self._proj_error is not None:
            raise self._proj_error
        if self._use_thread:
            pass  # the projector thread keeps the flips going
        elif self.trigger is not None and self.projector is not None:
            self._show_triggered()
        else:
            self._pace()
            self._show_untriggered()
        frame = self.camera.grab(self.timeout_s)
        arrival = self.clock()
        if self.checker._id_base is None and frame.trigger_count is None and self.projector is not None:
            # First frame (or the first after a camera restart): it answers the flip just made.
            self.checker.anchor_frame_id(frame.frame_id, self.tick)
        tagged, fs = self.checker.push(frame, arrival)
        self.tick += 1
        reason = "" if tagged is not None else self.checker.last_reason
        texture = tagged if tagged is not None and tagged.pattern == self.checker.texture_pattern else None
        return LoopEvent(tagged, frame, list(self.checker.confirmed), fs, arrival, reason, texture)

    def _pace(self) -> None:
        if not self.pace:
            return
        now = self.clock()
        if self._deadline > now:
            time.sleep((self._deadline - now) / 1e9)
        elif now - self._deadline > 4 * self.period_ns:
            self._deadline = now  # far behind (a stall): do not try to catch up
        self._deadline += self.period_ns

    def _show_untriggered(self) -> None:
        if self.projector is None:
            return
        pattern = self._pattern_at(self.tick, self.tick)
        flip_ns = self.projector.show(pattern) or self.clock()
        self.flips.record(Shown(self.tick, pattern, flip_ns))

    def _read_counter(self) -> int:
        from drivers.trigger.errors import TriggerResetError

        # A trigger that follows its own event lines answers without a serial round trip; the box is
        # still asked itself every QUERY_INTERVAL_NS, which is what notices a box gone silent or mad.
        now = time.monotonic_ns()
        if isinstance(self.trigger, PeekableTrigger) and now - self._last_query_ns < QUERY_INTERVAL_NS:
            read = self.trigger.peek_counter
        else:
            read, self._last_query_ns = self.trigger.counter, now  # type: ignore[union-attr]
        try:
            return int(read())
        except TriggerResetError:
            self._last_query_ns = 0  # the peeked count is stale after a reset: ask the box next time
            return -1

    def _show_triggered(self) -> None:
        before = self._read_counter()
        if before < self._count:
            self._resync()
            before = self._read_counter()
        pattern = self._pattern_at(before + 1, before)
        shown_ns = self.projector.show(pattern)  # type: ignore[union-attr]
        after = self._read_counter()
        flip_ns = shown_ns or self.clock()
        if after < before:  # reset during the show: nothing shown here can be trusted
            self._resync()
            return
        late = after != before
        self.flips.record(Shown(before + 1, pattern, flip_ns, late))
        if late:
            for t in range(before + 2, after + 2):  # the show landed somewhere in here
                self.flips.record(Shown(t, pattern, flip_ns, True))
        self._count = after

    def _resync(self) -> None:
        """The trigger's counter went back (a box that rebooted): forget the schedule, restart it.

        Frames of the old schedule still in the camera's buffer are refused by the checker (their
        count goes back or finds no flip), so the checker itself is not touched from here.
        """
        self.checker.stats.resyncs += 1
        self.flips.clear()
        self.trigger.start(self.rate_hz)  # type: ignore[union-attr]
        self._count = 0

    def close(self) -> None:
        """Stop (and, when the loop owns them, close) every device, even if one of them fails."""
        errors: list[BaseException] = []
        if self._proj_thread is not None:
            self._proj_stop.set()
            self._proj_thread.join(2.0)
            self._proj_thread = None
        actions: list[Callable[[], object]] = [
            lambda: self.projector.show(None) if self.projector is not None else None,
            lambda: self.trigger.stop() if self.trigger is not None else None,
            self.camera.stop,
        ]
        if self.owns_devices:
            actions += [
                self.camera.close,
                lambda: self.trigger.close() if self.trigger is not None else None,
                lambda: self.projector.close() if self.projector is not None else None,
            ]
        for action in actions:
            try:
                action()
            except Exception as exc:
                errors.append(exc)
        self._started = False
        if errors:
            raise errors[0]
