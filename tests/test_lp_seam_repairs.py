"""A seam plan's repair rounds keep the jerk-change rows at the seam's first nodes, as
its first solve does (`LPPlanner.seam_jerk_change`: the head satisfies them). Before,
the repair rounds linearized at their own last solution and dropped those rows as for a
moving start from nowhere: the nodal jerk zig-zagged on the first free intervals (sampled
at 1.1-1.56x the jerk limit, growing with each round) until the LP was infeasible, and
every seam attempt of the service's replans on cam-fp-hel45-D30 failed for a plan from
scratch (issue 13: that replan took 11.9 s, 7.8 s of it on the failed attempts)."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.sampling import sample_plan

#: the engine's first window on this path, and where its first replan starts (path units)
WINDOW_END = 1068.70
REPLAN_AT = 534.55


@pytest.fixture(scope="module")
def fiberpath_window():
    from bench.corpus import load_corpus

    (p,) = load_corpus("all", "cam-fp-hel45-D30*", True)
    m = p.config.machine
    return p, p.path(), m.limits.scaled(p.config.planner.margin), m


def test_a_replan_on_the_last_plan_repairs_at_its_seam(fiberpath_window):
    p, path, limits, machine = fiberpath_window
    geo = p.geometry()
    planner = LPPlanner()
    first = planner.plan(PlanRequest(path, limits, PathState(0.0), WINDOW_END,
                                     feed_cap=geo.feed_cap(), dt=machine.dt))
    prof = first.profile
    t = np.linspace(0.0, prof.duration, 40001)
    t_replan = float(t[np.searchsorted(prof.at(t)[0], REPLAN_AT)])
    s, v, a, _ = prof.at(np.array([t_replan]))[:, 0]
    assert v > 100.0  # a moving start on the last plan
    request = PlanRequest(path, limits, PathState(float(s), float(v), float(a)),
                          s + WINDOW_END, feed_cap=geo.feed_cap(), dt=machine.dt)
    replan = planner.plan(request)
    # continued at a seam (before: every seam attempt failed, planned from scratch) ...
    assert replan.info["seam"] is not None
    assert replan.info["repairs"] > 0  # ... through repair rounds
    # ... and the plan passes the checker from the replan's state on
    smp = sample_plan(path, replan.profile, machine.dt)
    assert check_positions(smp.pos, machine.limits, machine.dt).violations == 0
