"""The shortest stop (stream/plans.py) with fast-failing trials finds the stops the full
stop planner finds: never more than the bisection's 2 % longer, always within the limits."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry import fit_points, preset_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.lp import LPPlanner
from lookahead.stream.plans import CommittedPlan, shortest_stop


@pytest.fixture(scope="module")
def moving_plan():
    cfg = default_config().machine
    _, pts, _ = preset_points("tube-1450")
    path = fit_points(pts[:900], np.asarray(cfg.path_scale), "cubic")  # stroke + turnaround
    req = PlanRequest(path, cfg.limits, PathState(0.0), path.length, dt=cfg.dt)
    return cfg, req, CommittedPlan.anchor(path, LPPlanner().plan(req), 0, cfg.dt)


@pytest.mark.parametrize("fraction", [0.15, 0.4, 0.55, 0.7])
def test_fast_failing_search_finds_the_same_stops(moving_plan, fraction):
    cfg, req, plan = moving_plan
    k = int(fraction * (plan.k_end - plan.k_plan))
    state = plan.state(k, cfg.dt)
    tail = plan.samples(k - 2, 3, cfg.dt).pos
    base = PlanRequest(req.path, cfg.limits, state, plan.s_end, 0.0, None, cfg.dt)
    stops = [shortest_stop(HeuristicPlanner(margin=1.0, brake_within_limits=b), base, k,
                           tail, cfg.limits, plan.s_end) for b in (True, False)]
    full, fast = (st.s_end - state.s for st in stops)
    assert fast <= 1.02 * full + 1e-6
    assert full <= 1.02 * fast + 1e-6
    assert stops[1].s_end < plan.s_end - 1.0  # a real stop, not the plan's own end
    for st in stops:  # from the published tail to rest (held), by the checker
        pos = np.vstack([tail, st.samples(k + 1, st.k_end - k + 3, cfg.dt).pos])
        assert check_positions(pos, cfg.limits, cfg.dt).ok
