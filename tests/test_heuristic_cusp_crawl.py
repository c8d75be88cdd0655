"""Heuristic planner next to a true cusp (issue 4): the cells touching the corner must not
be capped at a crawl by the geometric singularity at the corner point itself, and the
sampled plan must still pass the finite-difference checker."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry import fit_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.sampling import sample_plan
from motion_bounds import rest_to_rest_duration

DT = 0.001
#: pchip through these points (X mm, C deg) has both axes at an extremum at the middle
#: point: a true cusp, the machine reverses there
CUSP_STROKES = [
    np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.5]]),
    np.array([[0.0, 0.0], [10.0, 3.0], [0.0, 1.0], [5.0, -4.0]]),
    np.array([[0.0, 0.0], [1.0, 50.0], [0.5, 0.0]]),
]


@pytest.mark.parametrize("points", CUSP_STROKES, ids=["tiny", "three-strokes", "tall-c"])
def test_plan_next_to_a_cusp_does_not_crawl(points):
    config = default_config()
    limits = config.machine.limits
    path = fit_points(points, config.machine.path_scale, "pchip")
    assert path.corners_s().size >= 1  # the case under test: a true cusp
    result = HeuristicPlanner().plan(PlanRequest(path, limits, PathState(0.0), path.length))
    duration = result.profile.duration
    # each stroke between points as a straight rest-to-rest move at the limits
    reference = sum(rest_to_rest_duration(step, limits) for step in np.diff(points, axis=0))
    # duration first: a crawling plan would last thousands of seconds (too long to sample)
    assert duration < 3.0 * reference, (duration, reference)
    report = check_positions(sample_plan(path, result.profile, DT).pos, limits, DT)
    assert report.ok, report.first
