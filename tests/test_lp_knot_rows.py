"""The LP's jerk rows at C1 knots (`lp.rows.knot_tangent_point`): the bound on |L| there,
J / sqrt(q) - knot sqrt(q), is convex, and its tangent at a q* above 3 J / knot excluded
q = 0. Linearized at their upper bounds, such rows made the whole-job LP of random pchip
paths infeasible on every grid ("highs returned Infeasible", 4-8 of 40 fuzzed paths,
`bench/fuzz_paths.py --method lp`)."""

from __future__ import annotations

import numpy as np
import pytest

from heuristic_paths import pchip_cusp, random_walk
from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.knots import c1_knot_caps, knot_jumps, knot_jumps_between
from lookahead.planning.lp.rows import GridGeometry, jerk_rows, knot_tangent_point
from lookahead.sampling import sample_plan

DT = 0.001
#: the fuzzer's case whose whole-job LP was infeasible at every grid
CASE = (6439, 3, 26, -0.651031437058171, -1.192092896e-07, "pchip")


@pytest.fixture(scope="module")
def pchip_walk():
    return random_walk(*CASE)


def test_knot_rows_hold_at_rest_whatever_the_linearization_point(pchip_walk):
    path, limits = pchip_walk
    s = np.linspace(0.0, path.length, 400)
    geo = GridGeometry.sample(path, s)
    knot = knot_jumps(path, s) / DT
    scale = np.ones(s.size)
    for level in (1e-6, 1.0, 1e3, 1e6):
        rows = jerk_rows(geo, limits.jmax, scale, np.full(s.size, level), 1e-12, knot)
        assert np.all(rows.upper >= 0.0), level  # q = 0 (A q = 0) satisfies every row
    # the case is not vacuous: at the highest level the plain tangent excludes q = 0
    top = np.max(knot, axis=1)
    assert np.any(1.5 * np.max(limits.jmax) - 0.5 * top * 1e6 < 0.0)


def test_the_tangent_point_is_clamped_only_above_the_bounds_zero():
    J = np.array([10.0, 10.0, 10.0, 10.0])
    knot = np.array([0.0, 2.0, 2.0, 2.0])
    q = np.array([100.0, 1.0, 5.0, 100.0])
    assert np.array_equal(knot_tangent_point(q, J, knot), [100.0, 1.0, 5.0, 5.0])


def test_the_fuzzed_pchip_walk_plans_whole_job_within_the_limits(pchip_walk):
    path, limits = pchip_walk
    request = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=DT)
    result = LPPlanner().plan(request)
    report = check_positions(sample_plan(path, result.profile, DT).pos, limits, DT)
    assert report.ok, report.first


def test_a_cusp_is_a_stop_not_a_c1_knot() -> None:
    """At a pchip cusp (both axes reverse: the fit's tangent vanishes, a corner) the LP
    reads no x_ss jump: the feed is 0 there, and the one-sided x_ss is not finite. Read
    as a knot, its cap held the two nodes either side at 5.6e-4 mm/s and the whole-job
    plan took 5.73 s (stop 51), against the heuristic's 1.82."""
    path, limits = pchip_cusp()
    (corner,) = path.corners_s()
    found = knot_jumps_between(path, 0.0, path.length)
    assert found is not None and found[0].size == path.breakpoints_s().size - 3
    assert not np.any(np.isclose(found[0], corner))
    s = np.sort(np.concatenate([np.linspace(0.0, path.length, 400), [corner]]))
    i = int(np.searchsorted(s, corner))
    assert np.all(np.isinf(c1_knot_caps(path, s, limits, DT)[i - 2:i + 3]))
    request = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=DT)
    lp = LPPlanner().plan(request)
    heuristic = HeuristicPlanner().plan(request)
    assert check_positions(sample_plan(path, lp.profile, DT).pos, limits, DT).ok
    assert lp.profile.duration <= 1.05 * heuristic.profile.duration
