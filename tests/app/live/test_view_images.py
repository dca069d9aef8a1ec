"""The view's fast panel images are the exported ones (what `slscan decode` writes): depth pixel for
pixel; stripes within 1 level (OpenCV's HSV->RGB rounds a pixel by its position in the SIMD lanes)."""

from __future__ import annotations

import numpy as np
import pytest

from app.decode.stripemap import StripeMap
from app.view import colourise_depth, depth_panel, stripe_colours, stripe_panel


@pytest.mark.parametrize("width", [1, 3])
def test_stripe_panel_is_stripe_colours(width):
    rng = np.random.default_rng(width)
    column = rng.uniform(-0.5, 1023.4, (60, 80)).astype(np.float32)
    column[rng.random(column.shape) < 0.3] = np.nan
    column[0, :4] = [-0.5, 0.5 - 1e-4, 2.5, 1023.4]  # stripe boundaries
    sm = StripeMap(column, np.where(np.isnan(column), 0, 1).astype(np.float32), stripe_width=width, period=256)
    out = stripe_panel(sm)
    assert np.abs(out.astype(int) - stripe_colours(sm)).max() <= 1
    assert not out[np.isnan(column)].any() and out[~np.isnan(column)].any(axis=1).all()


@pytest.mark.parametrize("rng_mm", [(500.0, 1000.0), None])
def test_depth_panel_is_colourise_depth(rng_mm):
    depth = np.random.default_rng(2).uniform(300, 1300, (60, 80)).astype(np.float32)
    depth[::7] = 0
    np.testing.assert_array_equal(depth_panel(depth, rng_mm), colourise_depth(depth, rng_mm))
    empty = np.zeros((4, 5), np.float32)
    np.testing.assert_array_equal(depth_panel(empty, rng_mm), colourise_depth(empty, rng_mm))


def test_redraw_planner_keeps_the_next_show_free():
    from app.view import RedrawPlanner

    plan = RedrawPlanner(period_s=1 / 60, margin_s=0.0015, starve_s=0.5)
    assert plan.may_run(10.0, None)  # no projector window: redraw on the timer alone
    plan.ran(0.008)  # "images" took 8 ms; the estimate follows it
    assert plan.phase == "draw"
    plan.cost_s["draw"] = 0.006
    # last show queued at t = 20.000: the next comes ~16.7 ms later
    assert plan.may_run(20.005, 20.0)  # 6 ms fits in the 10.2 ms left
    assert not plan.may_run(20.010, 20.0)  # 5.2 ms left: it would delay the next show
    assert plan.may_run(20.011, 20.0, flipped=True)  # a show was just served: the most room there is
    assert plan.ran(0.004) == "draw" and plan.phase == "images"
    plan.cost_s["images"] = 0.030  # a phase that never fits still runs every starve_s
    assert not plan.may_run(30.0, 29.999)
    assert plan.may_run(30.6, 30.599)
