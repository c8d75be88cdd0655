"""Heuristic planner: sampled plans pass the finite-difference checker, start and end at
rest on the path's ends, and continue a mid-motion state without a jump."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry.spline_path import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanningError, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic.scurve import reachable_feed, transition_distance
from lookahead.sampling import sample_plan

MACHINE = default_config().machine
DT = MACHINE.dt
SCALE = np.asarray(MACHINE.path_scale)
LIMITS = MACHINE.limits  # the winder's defaults


def winding_points(strokes: int = 2, stroke_mm: float = 200.0, dwell_deg: float = 90.0,
                   alpha_deg: float = 30.0, radius: float = 100.0) -> np.ndarray:
    """Straight helical strokes (1 mm points) joined by smooth half-sine turnarounds."""
    dc = stroke_mm / (radius * np.pi / 180.0 / np.tan(np.radians(alpha_deg)))
    pts, c, x, sign = [], 0.0, 0.0, 1.0
    for _ in range(strokes):
        f = np.linspace(0.0, 1.0, int(stroke_mm), endpoint=False)
        pts.append(np.c_[x + sign * f * stroke_mm, c + f * dc])
        c, x = c + dc, x + sign * stroke_mm
        th = np.linspace(0.0, 1.0, 60, endpoint=False)
        pts.append(np.c_[x + sign * 20.0 * np.sin(np.pi * th), c + dwell_deg * th])
        c += dwell_deg
        sign = -sign
    pts.append([[x, c]])
    return np.vstack(pts)


def plan_and_check(path, request):
    result = HeuristicPlanner().plan(request)
    samples = sample_plan(path, result.profile, DT)
    return result, samples, check_positions(samples.pos, request.limits, DT)


@pytest.mark.parametrize("fit", ["cubic", "pchip"])
def test_winding_rest_to_rest_passes_checker(fit):
    points = winding_points()
    path = fit_points(points, SCALE, fit)
    result, samples, report = plan_and_check(
        path, PlanRequest(path, LIMITS, PathState(0.0), path.length, dt=DT))
    assert report.ok, report.first
    assert result.info["verified"]
    np.testing.assert_allclose(samples.pos[0], points[0], atol=1e-9)
    np.testing.assert_allclose(samples.pos[-1], points[-1], atol=1e-6)
    np.testing.assert_allclose(samples.vel[[0, -1]], 0.0, atol=1e-6)
    np.testing.assert_allclose(samples.acc[[0, -1]], 0.0, atol=1e-6)
    # the straight strokes are X-bound: the X velocity gets close to its limit
    assert report.peak_fraction["v"][0] > 0.9


def shortest_window_end(planner, path, state: PathState) -> float:
    """The window end, to 0.1 %, at which the planner can only just stop: bisection on
    where it raises PlanningError (it must not fail beyond that)."""
    lo, hi = state.s, path.length
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        try:
            planner.plan(PlanRequest(path, LIMITS, state, mid, dt=DT))
            hi = mid
        except PlanningError:
            lo = mid
    return hi


def test_mid_motion_restart_is_continuous_and_within_limits():
    path = fit_points(winding_points(), SCALE, "cubic")
    planner = HeuristicPlanner()
    full = planner.plan(PlanRequest(path, LIMITS, PathState(0.0), path.length, dt=DT))
    first = sample_plan(path, full.profile, DT)
    rng = np.random.default_rng(7)
    moving = [k for k in range(10, len(first) - 10)
              if abs(full.profile.state_at(k * DT).a) > 1.0]
    for k in rng.choice(moving, size=4, replace=False):
        state = full.profile.state_at(k * DT)
        assert state.v > 0 and state.a != 0
        s_end = shortest_window_end(planner, path, state)
        again = planner.plan(PlanRequest(path, LIMITS, state, s_end, dt=DT))
        start = again.profile.state_at(0.0)
        assert start.s == pytest.approx(state.s, abs=1e-9)
        assert start.v == pytest.approx(state.v, abs=1e-6)
        assert start.a == pytest.approx(state.a, abs=1e-6)
        tail = sample_plan(path, again.profile, DT)
        joined = np.vstack([first.pos[:k], tail.pos])
        report = check_positions(joined, LIMITS, DT)
        assert report.ok, (k, report.first)
        end = again.profile.at(np.array([again.profile.duration]))
        assert end[0, 0] == pytest.approx(s_end, abs=1e-6)
        assert abs(end[1, 0]) < 1e-6


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(seed=st.integers(0, 2**31 - 1), limit_scale=st.floats(0.8, 3.0),
       npts=st.integers(3, 9), reversals=st.floats(0.0, 1.0),
       max_cell=st.sampled_from([None, 0.5, 2.0]))
# found by hypothesis: the axis jerk peaked at the end of a braking phase between the
# points of a 2 mm cell (verify.failing_phase_ends)
@example(seed=11333, limit_scale=3.0, npts=3, reversals=0.0, max_cell=2.0)
def test_random_wandering_paths_pass_checker(seed, limit_scale, npts, reversals, max_cell):
    """Random paths whose X goes back and forth: a step reverses X with a small C step
    (0.1-2 deg, a near-cusp) with probability `reversals`, else it goes anywhere.
    Long cells (max_cell) make the turns much narrower than a cell. Cubic fits only: a
    pchip fit turns a point where both axes reverse into a cusp of the parameterization,
    a corner the planner crawls into (see the report)."""
    rng = np.random.default_rng(seed)
    back = rng.random(npts) < reversals
    sign = np.where(np.arange(npts) % 2 == 0, 1.0, -1.0)
    dx = np.where(back, sign * rng.uniform(3.0, 30.0, npts), rng.normal(size=npts) * 15.0)
    dc = np.where(back, rng.uniform(0.1, 2.0, npts), rng.normal(size=npts) * 30.0)
    points = np.cumsum(np.vstack([[0.0, 0.0], np.c_[dx, dc]]), axis=0)
    path = fit_points(points, SCALE, "cubic")
    limits = AxisLimits(LIMITS.vmax * limit_scale, LIMITS.amax * limit_scale,
                        LIMITS.jmax * limit_scale)
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=DT)
    result = HeuristicPlanner(max_cell=max_cell).plan(request)
    samples = sample_plan(path, result.profile, DT)
    report = check_positions(samples.pos, limits, DT)
    assert report.ok, report.first
    np.testing.assert_allclose(samples.pos[-1], points[-1], atol=1e-6)


@pytest.mark.parametrize("v0", [0.0, 3.0, 40.0])
def test_reachable_feed_inverts_transition_distance(v0):
    for L in (1e-4, 0.05, 1.0, 30.0, 500.0):
        v1 = reachable_feed(v0, L, 2000.0, 20000.0)
        # rel 1e-6: v1 = v0 + dv loses digits of a tiny dv (1 ulp of 40 is 7e-15)
        assert transition_distance(v0, v1, 2000.0, 20000.0) == pytest.approx(L, rel=1e-6)


@pytest.mark.parametrize("preset", ["tube-1450", "tube-9570"])
def test_winding_presets_pass_checker(preset):
    from lookahead.geometry.winding import preset_points

    _, points, _ = preset_points(preset)
    path = fit_points(points, SCALE, "cubic")
    _result, samples, report = plan_and_check(
        path, PlanRequest(path, LIMITS, PathState(0.0), path.length, dt=DT))
    assert report.ok, report.first
    np.testing.assert_allclose(samples.pos[[0, -1]], points[[0, -1]], atol=1e-6)
    np.testing.assert_allclose(samples.vel[[0, -1]], 0.0, atol=1e-6)
