"""Local repair rounds (`lp.local_repair`, `LPPlanner.local_repair`): after the first
repair round, the LP is solved again only on zones around the sampled excesses, the other
nodes held at the last plan.

Before (issue 13, stop 47), every round re-solved the whole grid, which moved the feed
everywhere; on cam-fp-hel45-D30 the next check found new small excesses at new places,
round after round (10-12 rounds of ~75 ms per window), and the drift left the whole-job
plan 11.5 % slower than the one local rounds reach."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanningError, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.local_repair import held_rows, repair_zone, zone_rows
from lookahead.planning.lp.planner import (
    GLOBAL_REPAIR_ROUNDS,
    LOCAL_REPAIR_GROWTH,
    LOCAL_REPAIR_REACH,
    ZONE_LP_MAX_SHARE,
    GridPlan,
)
from lookahead.planning.lp.profile import profile_from_grid
from lookahead.planning.lp.rows import Rows
from lookahead.planning.sampled_check import SampledRatios
from lookahead.sampling import sample_plan

#: the end of the engine's first window on cam-fp-hel45-D30 (path units)
WINDOW_END = 1068.70


def _ratios(jerk_at: list[float], jerk: float = 1.05) -> SampledRatios:
    """Sampled ratios with jerk excesses at the times `jerk_at` (s), nothing else."""
    t = np.asarray(jerk_at, dtype=float)
    none = np.empty(0)
    return SampledRatios(none, none, np.full(t.size, jerk), none, none, t)


def test_the_zone_reaches_its_nodes_either_side_of_each_excess_interval():
    node_times = np.arange(40) * 0.1
    zone = repair_zone(_ratios([0.45, 3.05]), node_times, reach=3)
    # 0.45 s lies in interval 4 (nodes 4-5): nodes 1..8; 3.05 s in interval 30: 27..34
    assert np.flatnonzero(zone).tolist() == [*range(1, 9), *range(27, 35)]
    # within the ratio (<= 1) nothing is in the zone; an excess at the grid's ends clips
    assert not repair_zone(_ratios([0.45], jerk=1.0), node_times, 3).any()
    assert np.flatnonzero(repair_zone(_ratios([0.0, 3.95]), node_times, 2)).tolist() == \
        [0, 1, 2, 3, 36, 37, 38, 39]


def test_a_ratio_not_known_puts_every_node_in_the_zone():
    assert repair_zone(_ratios([0.45, 1.0], jerk=np.nan), np.arange(10) * 0.1, 1).all()


def test_rows_through_held_nodes_admit_the_held_plan_and_the_others_are_kept():
    A = sp.csr_matrix(np.array([[1.0, -1.0, 0.0], [0.0, 1.0, -1.0], [0.0, 0.0, 1.0]]))
    rows = Rows(A, np.array([-1.0, -1.0, 0.0]), np.array([1.0, 1.0, 2.0]))
    q = np.array([5.0, 0.5, 9.0])  # breaks rows 0 (4.5 > 1), 1 (-8.5 < -1) and 2 (9 > 2)
    held = np.array([True, False, False])
    widened = held_rows(rows, q, held)
    assert widened.upper.tolist() == [4.5, 1.0, 2.0]  # only row 0 runs through node 0
    assert widened.lower.tolist() == [-1.0, -1.0, 0.0]
    # the zone LP: node 0's share moved into row 0's bounds, row 1 and 2 as they were
    zone = zone_rows(widened, held, q)
    assert zone.A.toarray().tolist() == [[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]]
    assert zone.lower.tolist() == [-6.0, -1.0, 0.0]
    assert zone.upper.tolist() == [-0.5, 1.0, 2.0]


def test_rows_on_held_nodes_only_leave_the_zone_lp():
    A = sp.csr_matrix(np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]]))
    rows = Rows(A, np.zeros(2), np.full(2, 10.0))
    zone = zone_rows(rows, np.array([True, True, False]), np.array([1.0, 2.0, 0.0]))
    assert zone.A.shape == (1, 1)
    assert (zone.lower.tolist(), zone.upper.tolist()) == ([-2.0], [8.0])


class _Rounds:
    """A stand-in for the repair loop's `solve`: a zone narrower than `feasible_from`
    nodes is infeasible; records each call's zone size (None: a global round)."""

    def __init__(self, plan: GridPlan, feasible_from: int) -> None:
        self.plan, self.feasible_from, self.zones = plan, feasible_from, []

    def __call__(self, before=None, hold=None, **kw) -> GridPlan:
        self.zones.append(None if hold is None else int(np.sum(~hold)))
        if hold is not None and np.sum(~hold) < self.feasible_from:
            raise PlanningError("zone infeasible")
        return self.plan


@pytest.fixture
def long_grid():
    s = np.linspace(0.0, 100.0, 2001)
    q = np.full(s.size, 400.0)  # 20 mm/s throughout
    plan = GridPlan(s, q, 0.0)
    return plan, profile_from_grid(s, q, 0.0, 0.0)


def test_an_infeasible_zone_grows_and_the_next_round_starts_at_the_reach_that_worked(
        long_grid):
    plan, profile = long_grid
    t_mid = float(profile.s_of_t.x[1000] - profile.s_of_t.x[0]) + 1e-6
    ratios = _ratios([t_mid])
    planner = LPPlanner()
    first = LOCAL_REPAIR_REACH
    rounds = _Rounds(plan, feasible_from=2 * first + 3)  # the first zone is 2 reach + 2
    _, reach = planner._repair_round(rounds, None, plan, ratios, profile, None, first)
    assert rounds.zones == [2 * first + 2, 2 * first * LOCAL_REPAIR_GROWTH + 2]
    assert reach == first * LOCAL_REPAIR_GROWTH
    # reach 0 (the first GLOBAL_REPAIR_ROUNDS, or no zone was feasible): global at once
    rounds.zones.clear()
    assert planner._repair_round(rounds, None, plan, ratios, profile, None, 0)[1] == 0
    assert rounds.zones == [None]


def test_no_feasible_zone_ends_in_a_global_round_and_later_rounds_are_global(long_grid):
    plan, profile = long_grid
    t_mid = float(profile.s_of_t.x[1000] - profile.s_of_t.x[0]) + 1e-6
    rounds = _Rounds(plan, feasible_from=10**6)
    _, reach = LPPlanner()._repair_round(rounds, None, plan, _ratios([t_mid]), profile,
                                         None, LOCAL_REPAIR_REACH)
    # 66, 258, 1026 nodes infeasible; 4104 would be the whole grid: a global round
    assert rounds.zones == [2 * LOCAL_REPAIR_REACH * LOCAL_REPAIR_GROWTH**k + 2
                            for k in range(3)] + [None]
    assert reach == 0


@pytest.mark.parametrize("held_nodes", [8, 3])
def test_a_zone_lp_holds_its_nodes_and_solves_the_others(held_nodes, monkeypatch):
    """A zone of at most ZONE_LP_MAX_SHARE of the grid is an LP of its own, on the zone
    backend; a larger one the whole LP, on the planner's backend (its warm start)."""
    n = 10
    A = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n), format="csr")
    rows = [Rows(A, -np.ones(n - 1), np.ones(n - 1))]  # |q[i+1] - q[i]| <= 1
    held = np.arange(n) < held_nodes
    q_lo = np.where(held, 2.0, 0.0)
    q_hi = np.where(held, 2.0, 5.0)
    planner = LPPlanner()
    used = []
    for name in ("backend", "zone_backend"):
        backend = getattr(planner, name)
        monkeypatch.setattr(backend, "solve", lambda lp, _s=backend.solve, _n=name:
                            used.append(_n) or _s(lp))
    plan = GridPlan(np.linspace(0.0, 9.0, n), np.zeros(n), 0.0)
    q = planner._solve(plan, np.ones(n), q_lo, q_hi, rows, n, True, held=held)
    np.testing.assert_array_equal(q[held], 2.0)
    # the zone climbs from the held feed by 1 per node up to its cap
    np.testing.assert_allclose(q[~held], np.minimum(2.0 + np.arange(1, n - held_nodes + 1),
                                                    5.0), atol=1e-7)
    small = np.mean(~held) <= ZONE_LP_MAX_SHARE
    assert used == ["zone_backend" if small else "backend"]


@pytest.fixture(scope="module")
def d30_window():
    from bench.corpus import load_corpus

    (p,) = load_corpus("all", "cam-fp-hel45-D30*", True)
    m = p.config.machine
    request = PlanRequest(p.path(), m.limits.scaled(p.config.planner.margin), PathState(0.0),
                          WINDOW_END, feed_cap=p.geometry().feed_cap(), dt=m.dt)
    return request, m


def test_local_rounds_leave_the_held_nodes_as_they_were_and_the_plan_passes(
        d30_window, monkeypatch):
    request, machine = d30_window
    rounds = []  # (hold, the plan linearized at, the round's plan) of each local round
    solve_grid = LPPlanner.solve_grid

    def recording(self, *args, **kw):
        out = solve_grid(self, *args, **kw)
        if kw.get("hold") is not None:
            rounds.append((kw["hold"], kw["start_q"].copy(), out.q.copy()))
        return out

    monkeypatch.setattr(LPPlanner, "solve_grid", recording)
    result = LPPlanner().plan(request)
    assert result.info["repairs"] > GLOBAL_REPAIR_ROUNDS
    assert rounds, "no local repair round on a window that needs several rounds"
    for hold, last, q in rounds:
        assert 0 < np.sum(~hold) < hold.size / 2
        np.testing.assert_array_equal(q[hold], np.maximum(last[hold], 0.0))
        assert np.any(q[~hold] != last[~hold])  # the zone was solved again
    smp = sample_plan(request.path, result.profile, machine.dt)
    assert check_positions(smp.pos, machine.limits, machine.dt).violations == 0
