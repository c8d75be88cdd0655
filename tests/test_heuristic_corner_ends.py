"""A heuristic request that starts or ends at a corner of the path (a stretch between two
stops, as the LP's rest splice plans them) treats its end cells as beside a corner
(`path_limits.end_corners`): at a cusp the chain rule's x_ss and x_sss next to the corner
are cancellation, and read at the first budget point they capped a whole cell at a crawl."""

from __future__ import annotations

import numpy as np

from heuristic_paths import pchip_cusp
from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic.path_limits import end_corners
from lookahead.sampling import sample_plan

DT = 0.001


def _plan(path, limits, s0: float, s1: float):
    request = PlanRequest(path, limits, PathState(s0), s1, 0.0, None, DT)
    return HeuristicPlanner(margin=1.0, continue_last=False).plan(request)


def test_a_plan_from_rest_at_a_cusp_is_as_fast_as_one_from_just_past_it() -> None:
    """Before (stop 51): from the corner itself "no profile within the limits after 12
    repair rounds", from 1e-6 mm further on 1.89 s (a fuzzed walk's 15 mm stretch
    between two cusps: 4248 s against 7.6 s)."""
    path, limits = pchip_cusp()
    (corner,) = path.corners_s()
    at = _plan(path, limits, float(corner), path.length)
    past = _plan(path, limits, float(corner) + 1e-6, path.length)
    assert at.info.get("verified") is not False
    assert at.profile.duration <= 1.02 * past.profile.duration
    pos = sample_plan(path, at.profile, DT).pos
    assert np.allclose(pos[0], path.eval_s(np.array([corner]), order=0)[0][0])
    assert check_positions(pos, limits, DT).ok


def test_a_plan_to_rest_at_a_cusp_passes_the_checker() -> None:
    path, limits = pchip_cusp()
    (corner,) = path.corners_s()
    to = _plan(path, limits, 0.0, float(corner))
    short = _plan(path, limits, 0.0, float(corner) - 1e-6)
    assert to.profile.duration <= 1.02 * short.profile.duration
    assert check_positions(sample_plan(path, to.profile, DT).pos, limits, DT).ok


def test_end_corners_finds_corners_at_either_end_only() -> None:
    corners = np.array([2.0, 5.0])
    assert end_corners(corners, 2.0, 5.0, 1e-12) == (True, True)
    assert end_corners(corners, 2.0 + 1e-9, 4.0, 1e-12) == (False, False)
    assert end_corners(corners, 0.0, 2.0, 1e-12) == (False, True)
    assert end_corners(np.empty(0), 0.0, 2.0, 1e-12) == (False, False)
