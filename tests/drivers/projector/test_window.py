"""The pyglet projector on a real X server (Xvfb + Mesa): pixels read back from X equal the patterns."""

from __future__ import annotations

import itertools
import threading

import numpy as np
import pytest

from core.errors import DeviceError, InputError
from core.patterns import make_patterns
from drivers.base import PROJECTORS, Projector
from drivers.projector import PygletProjector
from drivers.projector.levels import levels_lut
from drivers.projector.window import ProjectorSetupError

pytestmark = pytest.mark.xserver

SIZE = (1024, 768)


@pytest.fixture(scope="module")
def projector(xserver):
    """One window for the module (opening one costs ~0.2 s); tests load what they need."""
    p = PygletProjector(0, SIZE, display=xserver)
    yield p
    p.close()


def _shown(projector, screen_grabber, images, index):
    projector.load(images)
    projector.show(index)
    return screen_grabber.grab()


def test_registered_and_implements_protocol(projector):
    assert PROJECTORS["pyglet"] is PygletProjector
    assert isinstance(projector, Projector)
    assert projector.size == SIZE
    assert projector.screen_index == 0


@pytest.mark.parametrize("index", [0, 1])
def test_two_shot_pixels_exact(projector, screen_grabber, index):
    ps = make_patterns("two-shot", SIZE)
    got = _shown(projector, screen_grabber, ps.images, index)
    np.testing.assert_array_equal(got, ps.images[index])


def test_one_shot_pixels_exact(projector, screen_grabber):
    ps = make_patterns("one-shot", SIZE, stripe_width=3)
    np.testing.assert_array_equal(_shown(projector, screen_grabber, ps.images, 0), ps.images[0])


def test_graycode_pixels_exact(projector, screen_grabber):
    ps = make_patterns("graycode", SIZE)
    roles = ps.params["frames"]
    # The finest column bit (1-pixel stripes: any filtering or offset shows) and a row bit (orientation).
    finest_col = next(i for i, r in enumerate(roles) if r == {"kind": "column", "bit": 0, "inverse": False})
    row = next(i for i, r in enumerate(roles) if r == {"kind": "row", "bit": 5, "inverse": True})
    projector.load(ps.images)
    for i in (finest_col, row):
        projector.show(i)
        np.testing.assert_array_equal(screen_grabber.grab(), ps.images[i], err_msg=ps.names[i])


def test_random_image_exact_and_row0_is_top(projector, screen_grabber):
    rng = np.random.default_rng(5)
    noise = rng.integers(0, 256, (SIZE[1], SIZE[0], 3), dtype=np.uint8)
    marker = np.zeros_like(noise)
    marker[0, :, 0] = 255  # red top row, green left column only
    marker[:, 0, 1] = 255
    projector.load([noise, marker])
    projector.show(0)
    np.testing.assert_array_equal(screen_grabber.grab(), noise)
    projector.show(1)
    top = screen_grabber.grab(0, 0, SIZE[0], 2)
    assert (top[0, 1:] == (255, 0, 0)).all() and (top[1, 1:] == 0).all()
    assert tuple(top[0, 0]) == (255, 255, 0)


def test_show_none_is_black(projector, screen_grabber):
    ps = make_patterns("two-shot", SIZE)
    assert _shown(projector, screen_grabber, ps.images, 0).any()
    projector.show(None)
    assert not screen_grabber.grab().any()
    assert projector.current is None


def test_levels_applied_to_uploaded_patterns(projector, screen_grabber):
    ramp = np.broadcast_to(np.arange(SIZE[0], dtype=np.uint32)[None, :, None] % 256, (SIZE[1], SIZE[0], 3))
    ramp = np.ascontiguousarray(ramp.astype(np.uint8))
    projector.load([ramp])
    try:
        projector.set_levels(gamma=2.2, brightness=0.5)
        projector.show(0)
        expected = levels_lut(2.2, 0.5)[ramp]
        assert not np.array_equal(expected, ramp)
        np.testing.assert_array_equal(screen_grabber.grab(), expected)
    finally:
        projector.set_levels()
    projector.show(0)
    np.testing.assert_array_equal(screen_grabber.grab(), ramp)


def test_flip_log_records_index_and_increasing_times(projector):
    projector.load(make_patterns("two-shot", SIZE).images)
    projector.flips.clear()
    returned = [projector.show(i) for i in (0, 1, None, 1)]
    log = list(projector.flips)
    assert [i for i, _ in log] == [0, 1, None, 1]
    assert [t for _, t in log] == returned
    assert all(b > a for a, b in itertools.pairwise(returned))


def test_run_alternates_at_60hz_and_reports_interval_and_jitter(projector):
    projector.load(make_patterns("two-shot", SIZE).images)
    seen: list[int | None] = []
    stats = projector.run([0, 1], 60, seconds=2.0, on_flip=lambda i, index, t: seen.append(index))
    print(f"\nprojector 60 Hz alternation on Xvfb: {stats.summary()}")
    assert seen[:4] == [0, 1, 0, 1] and len(seen) == stats.flips
    # Sane bounds only: deadline pacing never runs faster than asked, the count matches the time.
    assert 20 <= stats.flips <= 2.0 * 60 + 1  # a loaded 2-core machine may miss many refreshes
    assert 16.0 <= stats.mean_ms <= 100.0
    assert 0.0 <= stats.jitter_ms < stats.mean_ms
    assert stats.min_ms > 0


def test_run_shows_each_pattern_in_order(projector, screen_grabber):
    ps = make_patterns("two-shot", SIZE)
    projector.load(ps.images)
    mismatches = []

    def check(i, index, t):
        if not np.array_equal(screen_grabber.grab(), ps.images[index]):
            mismatches.append(i)

    stats = projector.run([0, 1], None, frames=4, on_flip=check)
    assert stats.flips == 4 and mismatches == []


def test_request_stop_from_another_thread(projector):
    projector.load(make_patterns("two-shot", SIZE).images)
    timer = threading.Timer(0.3, projector.request_stop)
    timer.start()
    stats = projector.run([0, 1], 60, seconds=20)
    timer.join()
    assert projector.stop_requested
    assert 3 <= stats.flips <= 60  # stopped after ~0.3 s, not 20 s


def test_bad_pattern_shapes_and_indices_are_typed_errors(projector):
    with pytest.raises(InputError, match=r"pattern 1 is uint8 \(768, 1000, 3\)"):
        projector.load([np.zeros((768, 1024, 3), np.uint8), np.zeros((768, 1000, 3), np.uint8)])
    with pytest.raises(InputError, match="pattern 0 is float64"):
        projector.load([np.zeros((768, 1024, 3))])
    projector.load([np.zeros((768, 1024, 3), np.uint8)])
    with pytest.raises(InputError, match="pattern index 1 is out of range"):
        projector.show(1)


def test_other_thread_is_refused(projector):
    errors = []

    def use():
        try:
            projector.show(None)
        except RuntimeError as exc:
            errors.append(str(exc))

    t = threading.Thread(target=use)
    t.start()
    t.join()
    assert errors and "thread that opened it" in errors[0]


def test_screen_by_name_and_bad_screens(display):
    with pytest.raises(DeviceError, match=r"screen 3 does not exist on display ':\d+' \(0: screen 1024x768\+0\+0\)"):
        PygletProjector(3)
    with pytest.raises(DeviceError, match="no screen named 'HDMI-9'"):
        PygletProjector("HDMI-9")
    with pytest.raises(ProjectorSetupError, match="is 1024x768, not the projector's 1920x1080"):
        PygletProjector(0, "1920x1080")


def test_open_by_name_then_close_is_idempotent(display, screen_grabber):
    p = PygletProjector("screen", [1024, 768])
    try:
        assert p.screen_index == 0
        p.load([np.full((768, 1024, 3), 77, np.uint8)])
        p.show(0)
        assert (screen_grabber.grab(500, 300, 8, 8) == 77).all()
    finally:
        p.close()
    p.close()
    with pytest.raises(DeviceError, match="is closed"):
        p.show(None)


def test_window_owned_by_a_worker_thread(display, screen_grabber):
    """The capture loop may run the projector on its own thread: open, load, show and close there."""
    ps = make_patterns("two-shot", SIZE)
    result: dict = {}

    def worker():
        try:
            with PygletProjector(0, SIZE) as p:
                p.load(ps.images)
                p.show(1)
                result["pixels"] = screen_grabber.grab()
                result["stats"] = p.run([0, 1], 60, frames=10)
        except Exception as exc:  # reported to the test thread below
            result["error"] = exc

    t = threading.Thread(target=worker)
    t.start()
    t.join(30)
    assert "error" not in result, result.get("error")
    np.testing.assert_array_equal(result["pixels"], ps.images[1])
    assert result["stats"].flips == 10
