"""Heuristic planner from a start state above the request's limits (the service replans
mid-motion after an override down or a lower feed cap): it brakes within the limits the
start came from and then keeps the new ones, or raises PlanningError."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.geometry.spline_path import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedCap, PlanningError, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.sampling import sample_plan
from test_heuristic_plans import DT, LIMITS, SCALE, winding_points

F = 0.5  # override: limits time-scaled by F (v F, a F^2, j F^3)
SLOW = AxisLimits(LIMITS.vmax * F, LIMITS.amax * F**2, LIMITS.jmax * F**3)


@pytest.fixture(scope="module")
def full_plan():
    path = fit_points(winding_points(), SCALE, "cubic")
    from lookahead.planning.base import PathState

    result = HeuristicPlanner().plan(PlanRequest(path, LIMITS, PathState(0.0), path.length,
                                                 dt=DT))
    return path, result, sample_plan(path, result.profile, DT)


@pytest.mark.parametrize("pick", ["full_feed", "full_acceleration"])
def test_override_down_brakes_within_the_original_limits_to_the_new_cap(full_plan, pick):
    path, full, first = full_plan
    states = full.profile.at(np.arange(len(first)) * DT)
    k = int(np.argmax(states[1] if pick == "full_feed" else states[2]))
    state = full.profile.state_at(k * DT)
    cap_v = 0.3 * state.v if pick == "full_feed" else 0.5 * state.v
    cap = FeedCap(np.array([0.0, path.length]), np.array([cap_v]))
    request = PlanRequest(path, SLOW, state, path.length, feed_cap=cap, dt=DT)
    result = HeuristicPlanner().plan(request)
    assert result.info["verified"]
    tail = sample_plan(path, result.profile, DT)
    report = check_positions(np.vstack([first.pos[:k], tail.pos]), LIMITS, DT)
    assert report.ok, report.first
    start = result.profile.state_at(0.0)
    assert start.v == pytest.approx(state.v, abs=1e-6)
    assert start.a == pytest.approx(state.a, abs=1e-6)
    # from some time on the feed stays at or below the new cap; it gets there no later
    # than braking along X alone at the new (slow) limits would
    t = np.arange(len(tail)) * DT
    feed = result.profile.at(t)[1]
    above = np.nonzero(feed > cap_v * (1 + 1e-6))[0]
    t_cap = t[above[-1] + 1] if above.size else 0.0
    bound = (state.v - cap_v) / SLOW.amax[0] + SLOW.amax[0] / SLOW.jmax[0] + 0.1
    assert t_cap <= bound
    end = result.profile.at(np.array([result.profile.duration]))
    assert end[0, 0] == pytest.approx(path.length, abs=1e-6)
    assert abs(end[1, 0]) < 1e-6


def test_start_above_limits_in_too_short_a_window_raises(full_plan):
    path, full, first = full_plan
    states = full.profile.at(np.arange(len(first)) * DT)
    k = int(np.argmax(states[1]))
    state = full.profile.state_at(k * DT)
    request = PlanRequest(path, SLOW, state, state.s + 1.0, dt=DT)
    with pytest.raises(PlanningError):
        HeuristicPlanner().plan(request)
