"""A replan from a state on the last plan's own brake, which no layout plans under this
window's cells and segments (their budgets a hair tighter there), is planned on finer
bands (`HeuristicPlanner._rescue_plan`) instead of being refused. The state: a replan-
continuity state on the B-spline corners (braking at 99 mm/s, -487 mm/s^2 towards a
corner), refused with "no brake within the limits" before."""

from __future__ import annotations

import numpy as np
from bench.corpus import load_corpus

from lookahead.planning.base import PathState, PlanRequest
from lookahead.stream.engine import horizon_length
from lookahead.stream.planners import make_planner


def test_braking_start_that_the_layouts_refuse_is_planned():
    p = load_corpus("fast", pattern="c-corners-bspline-2d")[0]
    cfg, m = p.config, p.config.machine
    path = p.path()
    lim = m.limits.scaled(cfg.planner.margin)
    window = horizon_length(lim, np.asarray(m.path_scale, float), cfg.planner.horizon_s)
    start = PathState(165.55774912240233, 99.09283911523147, -486.7026652881708)
    request = PlanRequest(path, lim, start, min(path.length, start.s + window), 0.0,
                          p.geometry().feed_cap(), m.dt)
    result = make_planner("heuristic").plan(request)
    assert result.info["verified"]
    end = result.profile.state_at(result.profile.duration)
    assert abs(end.s - request.s_end) <= 1e-6 * request.s_end
    assert end.v <= 1e-6


def test_start_above_the_default_shares_limit_is_planned_not_braked():
    """A replan on a circle at 205 mm/s, on a plan the wide shares made: above the feed
    limit of the planner's default shares, so it was taken for a start above the limits,
    and its brake (under those shares) failed: "no brake within the limits". The start
    limit is now the most permissive layout's."""
    p = load_corpus("fast", pattern="n-circle-R30")[0]
    cfg, m = p.config, p.config.machine
    path = p.path()
    lim = m.limits.scaled(cfg.planner.margin)
    window = horizon_length(lim, np.asarray(m.path_scale, float), cfg.planner.horizon_s)
    start = PathState(77.22796178359889, 205.26546018633388, -592.3367886837647)
    request = PlanRequest(path, lim, start, min(path.length, start.s + window), 0.0,
                          p.geometry().feed_cap(), m.dt)
    result = make_planner("heuristic").plan(request)
    assert result.info["verified"]
    assert "brake_scale" not in result.info
