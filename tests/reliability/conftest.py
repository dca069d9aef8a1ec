"""Reliability fixtures: one virtual rig (320x240) and its decoder, shared; fresh devices per test.

Building the rig is the slow part (seconds on this machine), so every test gets new devices over
the same rig (`SimBench(rig, ...)`: its own clock, flips, faults and camera truth).
"""

from __future__ import annotations

import pytest

from app.capture import CaptureLoop
from app.live_pipeline import LiveDecoder
from app.session import Session, build_session
from app.texture import with_texture
from drivers.sim.devices import SimBench, SimDevices, devices_from_bench, parse_faults

SMALL = {"camera_size": [320, 240]}


@pytest.fixture(scope="session")
def rig_session() -> tuple[Session, LiveDecoder]:
    session = build_session(None, sim_overrides=SMALL)
    return session, session.processor()


def fresh_devices(session: Session, faults: list | None = None, *, stepped: bool = False, seed: int = 0) -> SimDevices:
    """New camera/projector/trigger over the session's rig, the patterns loaded, faults as in config sim.faults."""
    bench = SimBench(session.sim.rig, stepped=stepped, faults=parse_faults(faults or []), seed=seed)
    dev = devices_from_bench(bench)
    dev.projector.load(with_texture(session.patterns))  # (as Session.make_loop: the white texture frame last)
    return dev


def make_loop(session: Session, dev: SimDevices, trigger=None, timeout_s: float = 3.0) -> CaptureLoop:
    """The live capture loop over these devices (the same constructor Session.make_loop uses)."""
    return CaptureLoop(
        dev.camera,
        dev.projector,
        trigger if trigger is not None else dev.trigger,
        session.scheme,
        len(session.patterns),
        rate_hz=session.rate_hz,
        timeout_s=timeout_s,
    )


def mispaired(dev: SimDevices, framesets) -> list[tuple[int, ...]]:
    """Sets in which frame p did not really see pattern p (the rig's truth), or frames not consecutive."""
    bad = []
    for fs in framesets:
        ids = fs.frame_ids
        truth = [dev.camera.truth(i) for i in ids]
        if truth != list(range(len(ids))) or sorted(ids) != list(range(min(ids), min(ids) + len(ids))):
            bad.append(ids)
    return bad
