"""OSQP backend of the LP: converges on the feed problems, agrees with HiGHS, and never hands
back a profile the finite-difference checker rejects (it raises PlanningError instead)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry import fit_points
from lookahead.geometry.winding import preset_points
from lookahead.planning.base import PathState, PlanningError, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.rows import Rows
from lookahead.planning.lp.solve import HighsBackend, OsqpBackend, ScaledLP
from lookahead.sampling import sample_plan


@pytest.fixture(scope="module")
def window_request() -> PlanRequest:
    """The first ~600 mm of tube-1450 from rest to rest: one streaming window."""
    cfg = default_config()
    _, points, _ = preset_points("tube-1450")
    path = fit_points(points, cfg.machine.path_scale)
    return PlanRequest(path, cfg.machine.limits, PathState(0.0, 0.0, 0.0),
                       min(600.0, path.length), dt=cfg.machine.dt)


def ramp_lp(n: int = 40) -> ScaledLP:
    """A small feed-like LP: 0 <= q_i <= cap_i, q_0 = 0, |q_i+1 - q_i| <= step_i, with
    caps and steps that vary so that several rows bind."""
    rng = np.random.default_rng(7)
    cap = rng.uniform(50.0, 100.0, n)
    lower, upper = np.zeros(n), cap.copy()
    upper[0] = 0.0
    diff = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n)).tocsr()
    step = rng.uniform(5.0, 20.0, n - 1)
    rows = Rows(diff, -step, step)
    return ScaledLP.build(np.ones(n), lower, upper, rows)


def test_osqp_matches_highs_on_a_small_lp():
    lp = ramp_lp()
    highs = HighsBackend().solve(lp)
    osqp_out = OsqpBackend().solve(lp)
    assert highs.ok and osqp_out.ok, osqp_out.status
    assert osqp_out.iterations > 0
    # same optimum (objective and point) to within the solver tolerance
    np.testing.assert_allclose(osqp_out.q, highs.q, atol=2e-3 * float(np.max(highs.q)))
    z = osqp_out.q / lp.q_scale
    assert np.all(z >= lp.lower) and np.all(z <= lp.upper)


def test_osqp_rejects_an_unconverged_answer():
    """One ADMM iteration is far from feasible: the backend must say so, not accept it."""
    out = OsqpBackend(max_iter=1).solve(ramp_lp())
    assert not out.ok


def test_osqp_window_passes_checker_and_matches_highs(window_request):
    """The contract allows PlanningError, but OSQP converges on this window (measured), so
    a PlanningError here is a regression and fails the test."""
    req = window_request
    res = LPPlanner(solver="osqp").plan(req)
    rep = check_positions(sample_plan(req.path, res.profile, req.dt).pos, req.limits, req.dt)
    assert rep.ok, rep.first
    assert res.info["solver"] == "osqp"
    reference = LPPlanner(solver="highs").plan(req)
    assert res.profile.duration == pytest.approx(reference.profile.duration, rel=0.03)


def test_osqp_planner_raises_when_the_solver_gives_up(window_request):
    planner = LPPlanner(solver="osqp")
    planner.backend = OsqpBackend(max_iter=1)
    with pytest.raises(PlanningError):
        planner.plan(window_request)
