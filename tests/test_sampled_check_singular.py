"""The LP's analytic check (`sampled_check.analytic_ratios`) where ds/du = 0: a pchip
knot at which every axis has an extremum is a corner the plan passes at rest, and its
s-derivatives there are 0/0 (NaN) or rounding. One NaN sample made `SampledRatios.worst`
skip the whole jerk array (Python's max() with NaN), so a fuzzed pchip walk's whole-job
LP plan left the planner 4.2x over the jerk limit (`bench/fuzz_paths.py --method lp`,
case 2069)."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.geometry.fits import fit_path
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.rows import GridGeometry
from lookahead.planning.sampled_check import SampledRatios, analytic_ratios, fill_undefined

LIMITS = AxisLimits(np.array([50.0, 50.0]), np.array([500.0, 500.0]),
                    np.array([5000.0, 5000.0]))


@pytest.fixture(scope="module")
def stop_knot():
    """A pchip path through 7 points whose 4th is an extremum of X and of Y (x_u = 0 in
    both axes: a corner at rest), and its whole-job LP plan without the planner's own
    check (which breaks the jerk limit, so that there is something to find)."""
    pts = np.array([[0, 0], [3, 1], [6, 3], [9, 6], [6, 5], [3, 6], [0, 6.5]], float)
    path = fit_path(pts, np.ones(2), "pchip")
    request = PlanRequest(path, LIMITS.scaled(0.95), PathState(0.0), path.length, dt=0.001)
    result = LPPlanner(verify=False).plan(request)
    return path, result


def test_worst_counts_a_nan_as_beyond_every_limit():
    ratios = SampledRatios(np.array([0.5]), np.array([0.5]), np.array([np.nan, 3.0]),
                           np.zeros(1), np.zeros(1), np.zeros(2))
    assert ratios.worst == np.inf


def test_undefined_ratios_take_their_neighbours():
    r = np.array([0.2, np.nan, 0.7, np.nan, np.nan])
    fill_undefined(r)
    assert np.array_equal(r, [0.2, 0.7, 0.7, 0.7, 0.0])


def test_a_sample_on_the_corner_does_not_hide_the_jerk(stop_knot):
    path, result = stop_knot
    corner = path.corners_s()
    assert corner.size == 1
    grid = result.info["grid_s"]
    geo = GridGeometry.sample(path, grid)
    knots_t = result.profile.s_of_t.x - result.profile.s_of_t.x[0]
    t_corner = float(knots_t[np.argmin(np.abs(grid - corner[0]))])
    # a sample step that puts one sample exactly at the corner (s = corner, sigma = 0)
    step = t_corner / np.round(t_corner / 0.0005)
    assert np.isclose(float(result.profile.at(np.array([t_corner]))[0][0]), corner[0],
                      rtol=0.0, atol=1e-12)
    ratios = analytic_ratios(path, result.profile, LIMITS, geo, step)
    assert np.all(np.isfinite(ratios.jerk)) and np.all(np.isfinite(ratios.acc))
    # the unverified plan breaks the jerk limit, and `worst` says so
    assert ratios.worst == ratios.jerk.max() > 1.0


def test_the_checked_plan_through_the_corner_passes_the_checker(stop_knot):
    from lookahead.checker import check_positions
    from lookahead.sampling import sample_plan

    path, _ = stop_knot
    request = PlanRequest(path, LIMITS.scaled(0.95), PathState(0.0), path.length, dt=0.001)
    result = LPPlanner().plan(request)
    report = check_positions(sample_plan(path, result.profile, 0.001).pos, LIMITS, 0.001)
    assert report.ok, report.first
