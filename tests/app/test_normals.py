"""The compiled normals (point_normals, every exported cloud's) follow grid_normals' numpy statement of the rule."""

from __future__ import annotations

import numpy as np
import pytest

from app.normals import grid_normals, point_normals


def surface(h: int = 60, w: int = 80, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A bumpy tilted surface with holes and a depth step (an edge the tangents must not cross), and its rays."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    ray = np.stack([(xx - w / 2) / 300.0, (yy - h / 2) / 300.0], axis=-1)
    depth = 500 + 0.8 * xx + 0.3 * yy + 4 * np.sin(xx / 7.0) * np.cos(yy / 5.0) + rng.normal(0, 0.05, (h, w))
    depth[:, w // 2 :] += 80  # a step of 16 %: across it, no tangent
    depth[rng.random((h, w)) < 0.05] = 0  # holes
    depth[:3, :] = 0
    return depth.astype(np.float32), ray


@pytest.mark.parametrize("window", [1, 3, 5])
def test_the_compiled_normals_are_grid_normals(window):
    depth, ray = surface()
    expected = grid_normals(depth, ray, window)[depth > 0]
    got = point_normals(depth, ray, window)
    none = ~np.isfinite(expected).all(axis=1)
    assert (~none).sum() > 0.8 * len(expected)
    assert none.any() or window > 1  # (the holes leave pixels without a tangent; a window fills them in)
    assert np.array_equal(got[none], np.zeros((none.sum(), 3), np.float32))
    assert np.abs(got[~none] - expected[~none]).max() < 1e-5
    assert np.allclose(np.linalg.norm(got[~none], axis=1), 1, atol=1e-6)


def test_an_even_window_is_refused():
    depth, ray = surface(10, 10)
    with pytest.raises(ValueError, match="odd"):
        point_normals(depth, ray, 4)
