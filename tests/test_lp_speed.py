"""The LP's speed rules (issue 13): a repair loop stuck at one place gives up for the split
grid at once, and the persistent HiGHS model starts a problem from the last basis of one
of its shape solved earlier."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import lookahead.planning.lp.planner as lp_planner
from lookahead.config import default_config
from lookahead.geometry.spline_path import fit_points
from lookahead.planning.base import PathState, PlanningError, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.planner import STUCK_REPEATS, stuck_at
from lookahead.planning.lp.solve import HighsBackend, MilpBackend
from test_lp_solvers import feed_lp, objective

MACHINE = default_config().machine


def test_stuck_at_counts_earlier_places_within_reach():
    s = np.arange(0.0, 100.0, 1.0)
    assert not stuck_at(s, [50.2], 50.4)  # one earlier round is not enough
    assert stuck_at(s, [50.2, 51.7], 50.4)
    assert not stuck_at(s, [50.2, 80.0], 50.4)  # one far away
    assert not stuck_at(s, [10.0, 80.0], 50.4)


def test_stuck_repairs_go_to_the_split_grid_at_once(monkeypatch):
    """A check that keeps failing at the same place: the first plan gives up after
    STUCK_REPEATS repairs (not max_repairs), and the next plan is on the grid split there."""
    th = np.linspace(0.0, np.pi, 120)
    path = fit_points(np.column_stack([100.0 * (1 - np.cos(th)), np.degrees(th)]),
                      np.asarray(MACHINE.path_scale))
    request = PlanRequest(path, MACHINE.limits, PathState(0.0), path.length)
    real = lp_planner.analytic_ratios

    def failing(path, profile, limits, geo, step):
        r = real(path, profile, limits, geo, step)
        jerk = r.jerk.copy()
        jerk[np.argmin(np.abs(r.t_jerk - 0.5 * profile.duration))] = 1.05  # mid-path
        return replace(r, jerk=jerk)

    monkeypatch.setattr(lp_planner, "analytic_ratios", failing)
    attempts: list[tuple[bool, str]] = []
    plan_once = LPPlanner._plan

    def recorded(self, *args, **kwargs):
        split = self._split is not None
        try:
            return plan_once(self, *args, **kwargs)
        except PlanningError as exc:
            attempts.append((split, str(exc)))
            raise

    monkeypatch.setattr(LPPlanner, "_plan", recorded)
    with pytest.raises(PlanningError):
        LPPlanner().plan(request)
    assert f"after {STUCK_REPEATS} repairs (stuck there)" in attempts[0][1]
    assert attempts[1][0]  # the split grid came next
    assert f"after {LPPlanner().max_repairs} repairs" in attempts[2][1]  # then as before


def test_highs_starts_from_the_basis_of_a_problem_of_the_same_shape():
    """A, then B of another shape, then A' of A's shape (another matrix): A' starts from
    A's basis (a warm solve) and meets the cold solve's objective."""
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    warm = HighsBackend()
    warm.MEMORY = 4  # off by default (HighsBackend.MEMORY)
    assert warm.solve(feed_lp(60, 1)).ok
    assert warm.solve(feed_lp(67, 2)).ok
    assert warm.warm_solves == 0
    again = feed_lp(60, 1, step_scale=0.7)
    out = warm.solve(again)
    assert warm.warm_solves == 1
    best = MilpBackend().solve(again)
    assert out.ok and best.ok
    assert objective(again, out.q) == pytest.approx(objective(again, best.q), rel=1e-7)


def _unstall_with(monkeypatch, feasible_floor: float) -> tuple[np.ndarray, list[float]]:
    """`LPPlanner._unstall` on 6 nodes (node 3 stalled) with an LP stand-in: every solve
    without a floor leaves node 3 at 0, a floor above `feasible_floor` (fraction of q_hi)
    is infeasible, one at or below it is met exactly. Returns q and the floors tried."""
    planner = LPPlanner()
    q_hi = np.full(6, 4.0)
    tried: list[float] = []

    def fake_solve(plan, weight, lo, hi, rows, n, record):
        f = float(lo[3] / q_hi[3])
        tried.append(f)
        if f > feasible_floor * (1 + 1e-12):
            raise PlanningError("lp: highs returned Infeasible")
        x = np.full(n, 2.0)
        x[3] = lo[3]
        return x

    monkeypatch.setattr(planner, "_solve", fake_solve)
    q0 = np.array([0.0, 2.0, 2.0, 0.0, 2.0, 0.0])
    q = planner._unstall(None, np.ones(6), q0, np.zeros(6), q_hi, [], {0: 0.0, 5: 0.0})
    return q, tried


def test_unstall_stops_its_floor_tries_when_the_lowest_floor_is_infeasible(monkeypatch):
    """All floors infeasible: after the first floor, the lowest one is tried and the rest
    skipped (a lower floor only relaxes the LP), with the stall left as before."""
    q, tried = _unstall_with(monkeypatch, feasible_floor=0.0)
    floors = [f for f in tried if f > 0]
    lowest = LPPlanner().stall_floor * 0.25 ** (lp_planner.STALL_FLOOR_TRIES - 1)
    assert floors == pytest.approx([LPPlanner().stall_floor, lowest])
    assert q[3] == 0.0


def test_unstall_with_a_feasible_low_floor_ends_where_the_full_sequence_does(monkeypatch):
    """The second try's floor is the highest feasible one: the plan takes it, as the tries
    from the top down did without the lowest-floor check."""
    second = LPPlanner().stall_floor * 0.25
    q, _ = _unstall_with(monkeypatch, feasible_floor=second)
    assert q[3] == pytest.approx(second * 4.0)
