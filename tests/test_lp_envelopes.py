"""The LP's start/stop envelopes (`lp.envelope.envelope_limits`): an axis that barely moves
in the window does not lend its limits to the whole tangent (`path_limits` does: on a path
whose small-limit axis barely moves, the envelopes then held the feed to a crawl); axes
that move keep `path_limits`."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.geometry import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.envelope import envelope_limits, path_limits
from motion_bounds import rest_to_rest_duration


@pytest.mark.parametrize("small", [1e-4, 1e-6])
def test_a_barely_moving_small_axis_does_not_slow_the_plan(small: float) -> None:
    # X: 400 mm at 200 mm/s, 2000 mm/s^2, 20000 mm/s^3; U moves `small` x as far with
    # limits 100 x `small` of X's: X binds everywhere (raw mm metric, both scales 1)
    n = 81
    x = np.linspace(0.0, 400.0, n)
    u = small * (x + 20.0 * np.sin(x / 60.0))
    path = fit_points(np.column_stack([x, u]), np.ones(2))
    lim = AxisLimits(vmax=np.array([200.0, 200.0 * 100 * small]),
                     amax=np.array([2000.0, 2000.0 * 100 * small]),
                     jmax=np.array([20000.0, 20000.0 * 100 * small]))
    d1 = path.eval_s(np.linspace(0.0, path.length, 200), order=1)[1]
    A, J = envelope_limits(d1, path.path_scale, lim)
    assert path_limits(path, lim) == pytest.approx((lim.amax[1], lim.jmax[1]))  # U's
    assert pytest.approx((2000.0, 20000.0)) == (A, J)  # X's, where X carries the tangent
    result = LPPlanner().plan(PlanRequest(path, lim, PathState(0.0), path.length))
    best = rest_to_rest_duration(np.array([path.length]), AxisLimits(
        vmax=lim.vmax[:1], amax=lim.amax[:1], jmax=lim.jmax[:1]))  # X alone
    # the margins (0.995 v, 0.98 a, 0.85 j) and the grid cost a few percent; with the
    # envelopes at U's limits the plan took 9.2 s (small 1e-4) and 90.7 s (1e-6), against
    # 2.28 s now and 2.20 s for X alone
    assert result.profile.duration < 1.1 * best


def test_axes_that_move_keep_the_path_limits() -> None:
    lim = AxisLimits(vmax=np.array([200.0, 9.0]), amax=np.array([2000.0, 50.0]),
                     jmax=np.array([20000.0, 800.0]))
    scale = np.array([1.0, 0.5])
    worst = (25.0, 400.0)  # C carrying the whole tangent (x'_C = 2)
    # C at a share |x'_C| scale_C of 2 % somewhere in the window: it moves, it bounds
    assert envelope_limits(np.array([[1.0, 0.0], [0.99, 0.04]]), scale, lim) == \
        pytest.approx(worst)
    # 0.5 %: C counts at its own tangent (50 / 0.01 = 5000 > 2000, X's): 80x and 50x
    assert envelope_limits(np.array([[1.0, 0.0], [0.99, 0.01]]), scale, lim) == \
        pytest.approx((2000.0, 20000.0))
    # the same share with C's limits 8x and 5x X's path limits: below ENVELOPE_LIFT, kept
    lim_c = AxisLimits(vmax=lim.vmax, amax=np.array([2000.0, 500.0]),
                       jmax=np.array([20000.0, 8000.0]))
    assert envelope_limits(np.array([[1.0, 0.0], [0.99, 0.01]]), scale, lim_c) == \
        pytest.approx((250.0, 4000.0))
