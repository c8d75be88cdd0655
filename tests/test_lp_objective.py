"""LPPlanner's `objective` option: the jerk passes' weights, and plans made with each
weighting pass the finite-difference checker (speed comparisons: bench/lp_quality.py)."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry.spline_path import fit_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.sampling import sample_plan

MACHINE = default_config().machine


@pytest.fixture(scope="module")
def path():
    """A short winder-like stroke: X sweeps 0..150 mm while C turns 270 deg."""
    th = np.linspace(0.0, np.pi, 120)
    pts = np.column_stack([75.0 * (1 - np.cos(th)) + 10.0 * np.sin(3 * th),
                           np.degrees(th) * 1.5])
    return fit_points(pts, np.asarray(MACHINE.path_scale))


def test_unknown_objective_is_refused():
    with pytest.raises(ValueError):
        LPPlanner(objective="energy")


def test_time_weights_favour_slow_nodes_and_keep_the_total():
    weight = np.full(5, 2.0)
    q_star = np.array([1.0, 4.0, 16.0, 64.0, 256.0])
    for name, power in (("time", 1.5), ("sqrt", 0.5)):
        w = LPPlanner(objective=name)._pass_weight(weight, q_star, True)
        assert np.isclose(w.sum(), weight.sum())
        assert np.allclose(w[:-1] / w[1:], 4.0**power)  # q* 4x apart -> ratio 4^power
    late = LPPlanner(objective="time-late")
    assert np.array_equal(late._pass_weight(weight, q_star, False), weight)
    assert not np.allclose(late._pass_weight(weight, q_star, True), weight)
    plain = LPPlanner(objective="distance")._pass_weight(weight, q_star, True)
    assert np.array_equal(plain, weight)


@pytest.mark.parametrize("objective", ["time", "time-late"])
def test_time_objective_plans_pass_the_checker(path, objective):
    limits, dt = MACHINE.limits, MACHINE.dt
    req = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=dt)
    res = LPPlanner(objective=objective, max_passes=2).plan(req)
    rep = check_positions(sample_plan(path, res.profile, dt).pos, limits, dt)
    assert rep.ok, rep
    assert res.profile.duration > 0.0


def test_both_solvers_plan_by_time_unless_told():
    assert LPPlanner().objective == "time"
    assert LPPlanner(solver="osqp").objective == "time"
    assert LPPlanner(solver="osqp", objective="distance").objective == "distance"


def test_a_seam_stalled_under_time_weights_is_retried_by_distance():
    """The engine's second window of a dwell-turnaround helix, seamed onto the first:
    under the time weights (q* = q_hi beyond the seam's head) the jerk pass left nodes at
    q = 0 that `_unstall` did not lift, and the job took 17.1 s against the whole-job
    plan's 8.2 s; with the distance retry it stays within 2 % of the whole job."""
    from bench.corpus import load_corpus
    from bench.corpus_bench import run_engine, run_whole

    (p,) = load_corpus("all", pattern="w-hel-R100-a45-dwell-2mm")
    engine, whole = run_engine(p, "engine-lp"), run_whole(p, "lp")
    assert engine["replans"] >= 2  # a seamed window, the case under test
    assert engine["fallbacks"] == 0 and engine["violations"] == 0
    assert whole["violations"] == 0
    assert engine["winding_s"] < 1.02 * whole["winding_s"]


def test_a_cold_plan_that_fails_by_time_is_planned_by_distance(path):
    """`_plan_cold` falls back to the distance weights (fuzz case 2809 failed by time
    alone); the planner keeps its own objective afterwards."""
    from lookahead.planning.base import PlanningError

    tried: list[str] = []

    class TimeFails(LPPlanner):
        def _plan_cold_by(self, request, fixed_head):
            tried.append(self.objective)
            if self.objective == "time":
                raise PlanningError("lp: the jerk LP has no solution")
            return super()._plan_cold_by(request, fixed_head)

    limits, dt = MACHINE.limits, MACHINE.dt
    req = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=dt)
    planner = TimeFails()
    res = planner.plan(req)
    assert tried == ["time", "distance"]
    assert planner.objective == "time"
    assert check_positions(sample_plan(path, res.profile, dt).pos, limits, dt).ok

    class AlwaysFails(LPPlanner):
        def _plan_cold_by(self, request, fixed_head):
            tried.append(self.objective)
            raise PlanningError("lp: the jerk LP has no solution")

    tried.clear()  # by distance from the start: nothing to fall back to, one try
    with pytest.raises(PlanningError):
        AlwaysFails(objective="distance").plan(req)
    assert tried == ["distance"]
