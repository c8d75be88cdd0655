"""Heuristic planner on paths that nearly reverse (near-cusps): the geometry grid resolves
the sharp peaks of d3x/ds3, and the finite-difference checker passes the sampled plan."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.geometry.spline_path import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic.path_limits import BudgetShares, build_grid, s_derivatives_at_u
from lookahead.sampling import sample_plan
from test_heuristic_plans import DT, LIMITS, SCALE

#: X strokes back and forth with small C steps (deg): near-cusps at the turns
ZIGZAG_STEPS = np.array([[24, 0.8], [-26, 1.2], [18, 0.6], [-28, 1.6], [-23, 10],
                         [-27, 1.4], [13.5, 0.25], [10, 23]])
FAST = AxisLimits(LIMITS.vmax * 2.5, LIMITS.amax * 2.5, LIMITS.jmax * 2.5)


@pytest.fixture(scope="module")
def zigzag():
    points = np.cumsum(np.vstack([[0.0, 0.0], ZIGZAG_STEPS]), axis=0)
    return fit_points(points, SCALE, "cubic")


def test_grid_resolves_the_third_derivative_peaks(zigzag):
    """Long cells (2 mm) around turns much narrower than a cell: the cells are split where
    the path speed ds/du varies, and the largest |x_sss| the grid sees is within 10 % of
    the largest on a dense evaluation of the path."""
    grid = build_grid(zigzag, 0.0, zigzag.length, DT, FAST, BudgetShares(), max_cell=2.0)
    assert np.diff(grid.edges).min() < 2.0 / 4**3  # refined at least three levels somewhere
    u = np.linspace(*zigzag.u_range, 2_000_001)  # dense in u: no arc-length inversion
    dense = np.abs(s_derivatives_at_u(zigzag, u)[3]).max(axis=0)
    seen = np.abs(grid.xsss).max(axis=(0, 1))
    np.testing.assert_array_less(0.9 * dense, seen)
    assert np.all(seen < 1.1 * dense)  # and they are real peaks of the path


@pytest.mark.parametrize("max_cell", [None, 2.0])
def test_zigzag_plan_passes_checker(zigzag, max_cell):
    planner = HeuristicPlanner(max_cell=max_cell)
    result = planner.plan(PlanRequest(zigzag, FAST, PathState(0.0), zigzag.length, dt=DT))
    assert result.info["verified"]
    samples = sample_plan(zigzag, result.profile, DT)
    report = check_positions(samples.pos, FAST, DT)
    assert report.ok, report.first
    np.testing.assert_allclose(samples.pos[-1], zigzag.eval_s(np.array([zigzag.length]),
                                                              order=0)[0][0], atol=1e-6)
