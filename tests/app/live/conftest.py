"""Shared fixtures of the live-session tests: one virtual-rig session and one decoder per module run."""

from __future__ import annotations

import numpy as np
import pytest

from app.session import build_session

# 320x240 keeps the per-calibration precomputation short; the bench runs the full 640x480.
SMALL = {"camera_size": [320, 240]}


@pytest.fixture(scope="session")
def sim_session():
    """The virtual rig of config/sim.yaml (face scene) at 320x240, with its processor built once."""
    session = build_session(None, sim_overrides=SMALL)
    processor = session.processor()
    return session, processor


def depth_agreement(depth: np.ndarray, gt, tol_mm: float = 2.0) -> tuple[float, float]:
    """(share of the decoded pixels within tol_mm of the true depth, share of the lit pixels decoded)."""
    truth = gt.depth
    have = depth > 0
    surface = gt.lit
    both = have & (truth > 0)
    if not have.any():
        return 0.0, 0.0
    good = np.abs(depth[both] - truth[both]) <= tol_mm
    return float(good.sum() / have.sum()), float((have & surface).sum() / surface.sum())
