"""The LP on random walks, where fuzzing the whole-job LP (`bench/fuzz_paths.py --method
lp`) found it failing or breaking a limit; one test per cause, each on its fuzzed case:

- a knot where a pchip fit nearly stops has a feed cap (`lp.knots.c1_knot_caps`) far
  below the feed around it, and the LP lands on it between nodes (`lp.knots.knot_steps`);
- such a knot's jump of x_ss is measured at one-sided limits in u (`KNOT_SIDE_DU`);
- a near-reversal's rest node is placed within a tenth of its radius of curvature of its
  sharpest point (`lp.grid.REVERSAL_PRECISION`)."""

from __future__ import annotations

import numpy as np
import pytest

from heuristic_paths import random_walk
from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner, default_grid_step
from lookahead.planning.lp.grid import MIN_STEP_FRACTION, near_reversals
from lookahead.planning.lp.knots import knot_caps, knot_jumps_between
from lookahead.sampling import sample_plan

DT = 0.001


def window_plan_is_clean(path, limits, s0: float, s1: float) -> None:
    request = PlanRequest(path, limits.scaled(0.95), PathState(s0), s1, dt=DT)
    result = LPPlanner().plan(request)
    report = check_positions(sample_plan(path, result.profile, DT).pos, limits, DT)
    assert report.ok, report.first


@pytest.fixture(scope="module")
def deep_knot():
    """Case 2069: 3 axes, 48 points; the knot at s = 91.209 caps the feed at 0.07 units/s
    (the jump of x_ss against X's 61.6 units/s^3), the feed around is ~2 units/s and the
    grid's top feed 259."""
    return random_walk(2069, 3, 48, 0.0, -1.4499741498985341, "pchip")


def test_a_deep_knot_gets_nodes_as_close_in_time_as_elsewhere(deep_knot):
    path, limits = deep_knot
    plan_limits = limits.scaled(0.95)
    knots, caps = knot_caps(path, 89.0, 93.0, plan_limits, DT)
    deep = knots[np.argmin(caps)]
    assert abs(deep - 91.2088) < 1e-3 and np.min(caps) < 0.1
    request = PlanRequest(path, plan_limits, PathState(89.0), 93.0, dt=DT)
    nodes, _ = LPPlanner().grid(request)
    h = default_grid_step(path, plan_limits)
    near = np.diff(nodes)[np.abs(nodes[:-1] - deep) < 0.05]
    # finer than the feature and limit-curve floor of h / 64 (0.017 here), where the
    # landing on the cap took one interval at 4.2x jmax
    assert near.min() < 0.1 * MIN_STEP_FRACTION * h
    window_plan_is_clean(path, limits, 89.0, 93.0)


def test_a_knot_jump_is_read_at_the_knot_itself():
    """Case 7999: at the knot s = 3379.8733 (the fit nearly stops, ds/du = 0.009) x_ss of
    axis 3 goes from 50 to 539 within 1e-5; read 3.4e-4 to either side (1e-7 of the
    path's length) the jump was 150, and the plan crossed the knot at 1.03 jmax."""
    path, _ = random_walk(7999, 4, 53, 1.521785958184001, -1.1980477365727333, "pchip")
    knots, jump = knot_jumps_between(path, 3379.0, 3380.0)
    assert knots.size == 1
    left, right = path.eval_s(knots[0] + np.array([-1e-8, 1e-8]), 2)[2][:, 3]
    assert jump[0, 3] == pytest.approx(abs(right - left), rel=1e-3)
    assert jump[0, 3] > 400.0


def test_a_near_reversal_rest_is_at_its_sharpest_point():
    """Case 2: a 179 deg turn of radius 3.8e-5 on a grid of step 2.9; the rest node was
    1.4e-4 off the sharpest point, which the whole-job plan passed at 3.5x jmax (every
    repair stuck there)."""
    path, limits = random_walk(2, 2, 34, 1.122028703112408, 1.122028703112408, "cubic")
    h = default_grid_step(path, limits.scaled(0.95))
    rests = near_reversals(path, h)
    x = np.linspace(259.981, 259.983, 20001)
    k = np.max(np.abs(path.eval_s(x, 2)[2]), axis=1)
    sharpest, radius = x[np.argmax(k)], 1.0 / np.max(k)
    assert radius < 1e-4
    assert np.min(np.abs(rests - sharpest)) < 0.2 * radius
    window_plan_is_clean(path, limits, 0.0, path.length)
