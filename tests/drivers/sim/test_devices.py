"""Simulated camera / projector / trigger: tagging by trigger tick, real-time pacing, injected faults."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from app.config import load_config
from core.errors import DeviceError, InputError
from drivers.base import CAMERAS, PROJECTORS, TRIGGERS, Camera, CameraTimeoutError, Projector, Trigger
from drivers.sim.devices import SimDevices, devices_from_bench, make_bench, make_sim_rig

SMALL = (160, 120)
GREEN = np.zeros((768, 1024, 3), np.uint8)
GREEN[..., 1] = 200
BLUE = np.zeros((768, 1024, 3), np.uint8)
BLUE[..., 2] = 200


def seen(frame) -> int:
    """Which of the two flat patterns a frame of the ideal white plane shows (0 green, 1 blue)."""
    g, b = frame.image[..., 1].mean(), frame.image[..., 2].mean()
    assert abs(max(g, b) - 200) < 1 and min(g, b) < 1
    return 0 if g > b else 1


def devices(faults=None, stepped: bool = True, buffer_frames: int = 8) -> SimDevices:
    bench = make_bench(
        scene="plane", ideal=True, stepped=stepped, faults=faults, camera_size=SMALL, buffer_frames=buffer_frames
    )
    dev = devices_from_bench(bench)
    dev.projector.load([GREEN, BLUE])
    dev.trigger.start(60)
    dev.camera.start()
    return dev


def run(dev: SimDevices, ticks: int, grabs: int) -> list:
    """Alternate the patterns tick by tick, then grab."""
    for k in range(ticks):
        dev.projector.show(k % 2)
        dev.trigger.step()
    return [dev.camera.grab(0.2) for _ in range(grabs)]


def test_registered_as_sim_and_sharing_one_rig() -> None:
    opts = {"scene": "plane", "ideal": True, "stepped": True, "camera_size": SMALL}
    cam, proj, trig = CAMERAS["sim"](**opts), PROJECTORS["sim"](**opts), TRIGGERS["sim"](**opts)
    assert isinstance(cam, Camera) and isinstance(proj, Projector) and isinstance(trig, Trigger)
    assert cam.bench is proj.bench is trig.bench
    assert proj.size == (1024, 768)


def test_registry_factories_share_one_rig_per_config(tmp_path: Path) -> None:
    cfg = tmp_path / "rig.yaml"
    cfg.write_text("sim:\n  scene: plane\n  camera_size: [160, 120]\n  ideal: true\n  stepped: true\n")
    config = load_config(cfg)
    cam, proj, trig = CAMERAS["sim"](config=config), PROJECTORS["sim"](config=config), TRIGGERS["sim"](config=config)
    assert cam.bench is proj.bench is trig.bench and cam.bench.rig.camera_size == SMALL
    proj.load([GREEN, BLUE])
    trig.start(60)
    cam.start()
    proj.show(1)
    trig.step()
    assert seen(cam.grab(0.2)) == 1


def test_each_frame_shows_the_pattern_of_its_trigger_tick() -> None:
    dev = devices()
    frames = []
    for k in range(6):
        dev.projector.show(k % 2)
        dev.trigger.step()
        frames.append(dev.camera.grab(0.2))
    assert [f.frame_id for f in frames] == [1, 2, 3, 4, 5, 6]
    assert [f.trigger_count for f in frames] == [1, 2, 3, 4, 5, 6]
    assert [seen(f) for f in frames] == [0, 1, 0, 1, 0, 1]
    assert all(f.pattern is None for f in frames)  # tagging is the capture loop's job
    assert [dev.camera.truth(f.frame_id) for f in frames] == [0, 1, 0, 1, 0, 1]
    ts = np.diff([f.timestamp_ns for f in frames])
    assert np.all(np.abs(ts - 1e9 / 60) <= 1)
    # a show() applies from the next tick on, as the flip record says
    assert [(c, i) for c, i, _ in dev.projector.flips[:3]] == [(0, 0), (1, 1), (2, 0)]


def test_dropped_duplicated_swapped_and_late_frames() -> None:
    dev = devices(faults=[{"kind": "drop", "at": [3]}])
    frames = run(dev, 5, 4)
    assert [f.frame_id for f in frames] == [1, 2, 4, 5] and [seen(f) for f in frames] == [0, 1, 1, 0]
    dev = devices(faults=[{"kind": "duplicate", "at": [2]}])
    frames = run(dev, 3, 4)
    assert [f.frame_id for f in frames] == [1, 2, 2, 3] and np.array_equal(frames[1].image, frames[2].image)
    dev = devices(faults=[{"kind": "swap", "at": [2]}])
    frames = run(dev, 4, 4)
    assert [f.frame_id for f in frames] == [1, 3, 2, 4] and [seen(f) for f in frames] == [0, 0, 1, 1]
    dev = devices(faults=[{"kind": "late_flip", "at": [3]}])
    frames = run(dev, 4, 4)
    assert [f.frame_id for f in frames] == [1, 2, 3, 4]
    assert [seen(f) for f in frames] == [0, 1, 1, 1]  # frame 3 still saw pattern 1: a mispair if trusted
    assert dev.camera.truth(3) == 1


def test_random_faults_are_reproducible_per_seed() -> None:
    def ids() -> list[int]:
        dev = devices(faults=[{"kind": "drop", "probability": 0.2}], buffer_frames=100)
        return [f.frame_id for f in run(dev, 60, 40)[:40]]

    a = ids()
    assert a == ids() and len(set(range(1, a[-1] + 1)) - set(a)) > 0


def test_disappearing_camera_raises_and_a_new_one_works() -> None:
    dev = devices(faults=[{"kind": "disappear", "at": [2]}])
    run(dev, 1, 1)
    dev.trigger.step()
    with pytest.raises(DeviceError, match="disappeared"):
        dev.camera.grab(0.2)
    with pytest.raises(DeviceError, match="disappeared"):
        dev.camera.grab(0.2)
    with pytest.raises(DeviceError):
        dev.camera.start()
    dev.bench.faults.clear()
    again = type(dev.camera)(dev.bench)
    again.start()
    dev.trigger.step()
    assert again.grab(0.2).frame_id == 3


def test_trigger_reset_restarts_the_counter() -> None:
    dev = devices(faults=[{"kind": "reset", "at": [3]}])
    dev.projector.show(0)
    dev.trigger.step(2)
    assert [dev.camera.grab(0.2).frame_id for _ in range(2)] == [1, 2]
    dev.trigger.step(2)  # tick 3 resets the box: tick 4 is its new 1
    assert dev.trigger.counter() == 1
    frames = [dev.camera.grab(0.2) for _ in range(2)]
    assert [f.frame_id for f in frames] == [3, 4]  # the camera's own counter goes on
    assert [f.trigger_count for f in frames] == [3, 1]
    assert [seen(f) for f in frames] == [0, 0]  # the projector still shows what it showed


def test_timeout_without_trigger_ticks() -> None:
    dev = devices()
    t = time.monotonic()
    with pytest.raises(CameraTimeoutError):
        dev.camera.grab(0.1)
    assert 0.09 < time.monotonic() - t < 1.0


def test_real_time_trigger_paces_frames_and_a_stall_loses_the_oldest() -> None:
    dev = devices(stepped=False, faults=[{"kind": "stall", "at": [10], "seconds": 0.5}], buffer_frames=16)
    t = time.monotonic()
    frames = []
    for k in range(30):
        dev.projector.show(k % 2)
        frames.append(dev.camera.grab(1.0))
    elapsed = time.monotonic() - t
    ids = [f.frame_id for f in frames]
    assert ids == sorted(ids) and ids[:10] == list(range(1, 11))
    assert ids[10] - ids[9] > 10  # the 30 frames exposed during the 0.5 s stall overflowed the 16 buffers
    assert dev.camera.dropped == ids[-1] - len(ids)
    assert 0.7 < elapsed < 3.0  # 30 frames at 60 Hz + 0.5 s stall (+ a busy machine)
    for f in frames:
        assert seen(f) == dev.camera.truth(f.frame_id)


def test_make_sim_rig_from_config(tmp_path: Path) -> None:
    cfg = tmp_path / "sim.yaml"
    cfg.write_text(
        "sim:\n  scene: plane\n  camera_size: [160, 120]\n  projector_size: [1024, 768]\n  ideal: true\n"
        "  stepped: true\n  effects: {ambient: 0.1}\n  faults: [{kind: drop, at: [2]}]\n"
    )
    dev = make_sim_rig(load_config(cfg))
    camera, projector, trigger = dev  # the three devices, sharing dev.rig
    assert camera.bench is projector.bench is trigger.bench is dev.bench
    assert dev.rig.camera_size == SMALL and dev.rig.options.ambient == 0.1 and dev.rig.options.noise is False
    dev.projector.load([GREEN, BLUE])
    dev.trigger.start(60)
    dev.camera.start()
    assert [f.frame_id for f in run(dev, 3, 2)] == [1, 3]
    cfg.write_text("sim:\n  scene: plane\n  warp: 9\n")
    with pytest.raises(InputError, match=r"'sim\.warp'"):
        make_sim_rig(load_config(cfg))
    cfg.write_text("sim:\n  scene: plane\n  faults: [{kind: explode, at: 1}]\n")
    with pytest.raises(InputError, match="explode"):
        make_sim_rig(load_config(cfg))


def test_default_config_builds_the_virtual_rig() -> None:
    dev = make_sim_rig(load_config())
    assert dev.rig.scene.name == load_config().get("sim.scene")
    assert dev.rig.camera_size == tuple(load_config().get("sim.camera_size"))
    with pytest.raises(InputError, match="pattern must be uint8 RGB 1024x768"):
        dev.projector.load([np.zeros((10, 10, 3), np.uint8)])


def test_free_run_without_trigger_and_no_frames_once_the_trigger_stops() -> None:
    bench = make_bench(scene="plane", ideal=True, camera_size=SMALL)
    cam, proj, trig = devices_from_bench(bench)
    proj.load([GREEN, BLUE])
    cam.start()
    proj.show(1)
    f = cam.grab(0.2)  # no trigger yet: the camera free-runs on host time
    assert seen(f) == 1 and f.trigger_count is None
    trig.start(120)
    first = cam.grab(1.0)
    assert first.trigger_count == first.frame_id == 1 and seen(first) == 1  # what was on screen stays
    trig.stop()
    with pytest.raises(CameraTimeoutError):
        for _ in range(20):  # at most the buffered frames, then nothing
            cam.grab(0.05)
