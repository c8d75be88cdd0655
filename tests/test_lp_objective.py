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
    assert np.array_equal(LPPlanner()._pass_weight(weight, q_star, True), weight)


@pytest.mark.parametrize("objective", ["time", "time-late"])
def test_time_objective_plans_pass_the_checker(path, objective):
    limits, dt = MACHINE.limits, MACHINE.dt
    req = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=dt)
    res = LPPlanner(objective=objective, max_passes=2).plan(req)
    rep = check_positions(sample_plan(path, res.profile, dt).pos, limits, dt)
    assert rep.ok, rep
    assert res.profile.duration > 0.0
