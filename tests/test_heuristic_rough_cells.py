"""Rough cells (`path_limits.rough_cells`): where the geometry varies faster than a cell's
five points resolve (a polyline's 1 mm corner blends), the heuristic checks its plan by the
checker's finite differences there, since the grid points pass between the geometric
jerk's peaks. Found by the hypothesis test of tests/test_geometry_linear_fit.py: a plan the
grid check had passed was sampled at 1.035 jmax (20702 against 20000 mm/s^3 on X)."""

from __future__ import annotations

import numpy as np
import pytest

from heuristic_paths import random_polyline
from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry.fits import fit_path
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic import planner as heuristic_planner
from lookahead.planning.heuristic.path_limits import feed_limit, rough_cells
from lookahead.sampling import sample_plan

MACHINE = default_config().machine
SCALE = np.asarray(MACHINE.path_scale)


@pytest.fixture(scope="module")
def blends():
    """The failing example hypothesis found: sharp turns between 0.4-1 mm lines, blended
    within 1 mm, beside two 200 mm strokes."""
    pts = random_polyline([151.0, 1.0, 47.0, 45.0, 1.0, 136.0, 106.0, 1.0, 1.0],
                          [True, False, False, True, False, False, False, False, False],
                          [1.0, 1.0, 1.0, 200.0, 1.0, 200.0, 10.0 ** -0.375,
                           10.0 ** -0.0625, 1.0, 1.0], SCALE)
    path = fit_path(pts, SCALE, "linear", 1.0)
    limits = MACHINE.limits.scaled(default_config().planner.margin)
    return PlanRequest(path, limits, PathState(0.0), path.length, dt=MACHINE.dt)


def checked(request: PlanRequest):
    result = HeuristicPlanner(margin=1.0).plan(request)
    samples = sample_plan(request.path, result.profile, MACHINE.dt)
    return result, check_positions(samples.pos, MACHINE.limits, MACHINE.dt)


def test_the_blends_have_rough_cells(blends):
    planner = HeuristicPlanner(margin=1.0)
    grid, _ = planner._grid(blends, blends.start, blends.limits)
    vlim = feed_limit(grid, blends.limits, heuristic_planner.COARSE.shares)
    rough = rough_cells(grid, blends.limits, vlim)
    assert 0 < np.count_nonzero(rough) < 0.05 * grid.ncells


def test_a_plan_over_rough_cells_passes_the_checker(blends):
    result, report = checked(blends)
    assert result.info["verified"]
    assert report.ok, report.first


def test_without_the_rough_cells_check_the_plan_breaks_the_jerk_limit(blends, monkeypatch):
    """The cause, shown: with no cell rough, the grid check passes a plan the checker
    refuses for its jerk."""
    monkeypatch.setattr(heuristic_planner, "rough_cells",
                        lambda grid, limits, vlim: np.zeros(grid.ncells, dtype=bool))
    _, report = checked(blends)
    assert not report.ok and report.first.kind == "j"
