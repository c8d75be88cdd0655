"""C1-knot caps (`path_limits._c1_knot_zones`) are judged per knot: a pchip path whose
parametrization nearly stops at one knot (sigma ~ 1e-3, |x_ss| ~ 6e6 there) made every
other knot's acceleration jump look like rounding when the rounding scale was the window's
largest |x_ss|, and the plan cruised through those knots at 6x their caps (12x the jerk
limit in the checker). Found by fuzzing random pchip paths of 2-4 axes with limits of
random scales."""

from __future__ import annotations

import numpy as np
import pytest

from heuristic_paths import random_walk
from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic.path_limits import s_derivatives_at_u
from lookahead.sampling import sample_plan

DT = 0.001


@pytest.fixture(scope="module")
def wander():
    """A seeded random walk of 27 points in 2 axes of very different scales, pchip-fitted,
    with seeded limits (axis 1: 5.9 units/s, 27 units/s^2, 90 units/s^3)."""
    return random_walk(922, 2, 27, 0.2041682243127707, 1.3482320782172486, "pchip")


def test_a_near_stop_knot_does_not_hide_the_other_knots_jumps(wander):
    path, _ = wander
    knots = path.breakpoints_s()
    inner = knots[(knots > 0.0) & (knots < path.length)]
    inner = inner[~np.isin(inner, path.corners_s())]
    u = path.u_of_s(inner)
    sigma, _, left, _ = s_derivatives_at_u(path, u - 1e-9)
    _, _, right, _ = s_derivatives_at_u(path, u + 1e-9)
    scale = np.max(np.abs(np.concatenate([left, right], axis=1)), axis=1)
    jump = np.max(np.abs(right - left), axis=1)
    # the case: one knot's scale would have hidden jumps well above rounding at others
    assert np.max(scale) > 1e6 and np.min(sigma) < 1e-2
    hidden = jump < 1e-7 * np.max(scale)
    assert np.any(hidden & (jump > 1e-7 * scale))


def test_its_plan_slows_for_every_c1_knot(wander):
    path, limits = wander
    request = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=DT)
    result = HeuristicPlanner(margin=1.0).plan(request)
    report = check_positions(sample_plan(path, result.profile, DT).pos, limits, DT)
    assert report.ok, report.first
