"""A HiGHS basis carried from one window's LP to the next (`lp.basis_carry`): the mapping
by nearest node and row key, and the solves it starts, which must reach the same optimum
as a cold solve."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from lookahead.planning.lp.basis_carry import (
    MIN_ROW_SHARE,
    CarriedBasis,
    map_basis,
    nearest_nodes,
)
from lookahead.planning.lp.rows import Rows
from lookahead.planning.lp.solve import HighsBackend, MilpBackend, ScaledLP, row_keys
from test_lp_solvers import feed_lp, objective

LOWER, BASIC, UPPER = 0, 1, 2


def window_lp(start: int, n: int, seed: int = 5) -> ScaledLP:
    """Nodes start..start+n-1 of one long feed-like path (caps, steps and curvature
    bounds drawn once for the whole path, so two windows agree where they overlap), at
    rest at both window ends."""
    rng = np.random.default_rng(seed)
    total = start + n + 1
    cap, step = rng.uniform(50.0, 100.0, total), rng.uniform(5.0, 20.0, total)
    curv = rng.uniform(2.0, 8.0, total)
    idx = np.arange(start, start + n)
    upper = cap[idx].copy()
    upper[[0, -1]] = 0.0
    d1 = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n))
    d2 = sp.diags([np.ones(n - 2), -2.0 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2],
                  shape=(n - 2, n))
    rows = Rows(sp.vstack([d1, d2]).tocsr(), np.concatenate([-step[idx[:-1]], -curv[idx[:-2]]]),
                np.concatenate([step[idx[:-1]], curv[idx[:-2]]]))
    return ScaledLP.build(np.ones(n), np.zeros(n), upper, rows, nodes=idx.astype(float))


def test_nearest_nodes_inside_the_old_span_only():
    old = np.array([0.0, 1.0, 2.0, 3.0])
    new = np.array([-0.5, 0.4, 0.6, 2.9, 3.0, 3.2, np.nan])
    assert nearest_nodes(new, old).tolist() == [-1, 0, 1, 3, 3, -1, -1]
    # NaN columns in the old LP (elastic slacks) are never a node
    assert nearest_nodes(np.array([2.9]), np.r_[old, np.nan, np.nan]).tolist() == [3]
    assert nearest_nodes(np.array([1.0]), np.empty(0)).tolist() == [-1]


def test_map_basis_moves_statuses_onto_a_shifted_regridded_window():
    s = np.linspace(0.0, 59.0, 60)
    old = feed_lp(60, 1, nodes=s)
    k_old = row_keys(old.A, old.nodes)
    rng = np.random.default_rng(0)
    carried = CarriedBasis(s, k_old, rng.integers(0, 3, 60), rng.integers(0, 3, k_old.shape[0]))
    # the next window: shifted by 10.3 nodes (its nodes between the old ones), 5 longer
    new_nodes = np.linspace(10.3, 74.3, 65)
    new = feed_lp(65, 2, nodes=new_nodes)
    keys = row_keys(new.A, new.nodes)
    mapped = map_basis(carried, new.nodes, keys, LOWER, BASIC)
    assert mapped is not None
    cols, rows = mapped
    near = nearest_nodes(new_nodes, s)
    inside = near >= 0
    assert np.array_equal(cols[inside], carried.col_status[near[inside]])
    assert np.all(cols[~inside] == LOWER) and np.count_nonzero(~inside) == 16  # 59.3 .. 74.3
    # a row past the old window is fresh: its slack is basic
    past = new_nodes[new.A.indices[new.A.indptr[:-1]]] > 59.5
    assert np.all(rows[past] == BASIC)
    # a shared row takes the status of the old row starting at the nearest old node
    # with the same rank and entries
    first_new = new.A.indices[new.A.indptr[:-1]]
    first_old = old.A.indices[old.A.indptr[:-1]]
    checked = 0
    for r in np.flatnonzero(~past):
        j = near[first_new[r]]
        same = np.flatnonzero((first_old == j) & (k_old[:, 1] == keys[r, 1])
                              & (k_old[:, 2] == keys[r, 2]))
        if same.size:
            assert rows[r] == carried.row_status[same[0]]
            checked += 1
    assert checked > 80


def test_map_basis_refuses_a_window_that_shares_too_little():
    s = np.linspace(0.0, 59.0, 60)
    old = feed_lp(60, 1, nodes=s)
    carried = CarriedBasis(s, row_keys(old.A, s), np.zeros(60, dtype=int),
                           np.ones(old.A.shape[0], dtype=int))
    far = np.linspace(59.0 - 60 * MIN_ROW_SHARE / 2, 200.0, 60)  # overlaps < the share
    new = feed_lp(60, 1, nodes=far)
    assert map_basis(carried, far, row_keys(new.A, far), LOWER, BASIC) is None


@pytest.mark.parametrize("shift", [10.0, 10.3, 37.5])
def test_carried_start_reaches_the_cold_optimum(shift):
    """Window 2 (shifted, re-gridded, another size) starts from window 1's basis and ends
    at the optimum of a cold solve, its solution inside every row."""
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    n = HighsBackend.CARRY_MIN_COLUMNS + 50
    s = np.linspace(0.0, n - 1.0, n)
    first = feed_lp(n, 1, nodes=s)
    second = feed_lp(n + 7, 1, nodes=np.linspace(shift, shift + n + 6.0, n + 7))
    backend = HighsBackend()
    assert backend.solve(first).ok
    out = backend.solve(second)
    assert backend.carried_solves == 1
    cold = MilpBackend().solve(second)
    assert out.ok and cold.ok
    assert objective(second, out.q) == pytest.approx(objective(second, cold.q), rel=1e-7)
    z = out.q / second.q_scale
    Az = second.A @ z
    assert np.all(Az <= second.row_upper + 1e-7) and np.all(Az >= second.row_lower - 1e-7)


def test_carry_off_small_or_without_nodes_starts_cold():
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    small = HighsBackend()  # below CARRY_MIN_COLUMNS a cold solve is cheap
    small.solve(window_lp(0, 60))
    small.solve(window_lp(3, 64))
    s = np.linspace(0.0, 59.0, 60)
    off = HighsBackend()
    off.CARRY = False
    off.solve(feed_lp(60, 1, nodes=s))
    off.solve(feed_lp(64, 1, nodes=s + 3.0))
    plain = HighsBackend()
    plain.solve(feed_lp(60, 1))
    plain.solve(feed_lp(64, 1))
    assert off.carried_solves == 0 and plain.carried_solves == 0
    assert small.carried_solves == 0


def test_carry_saves_simplex_iterations_on_an_overlapping_window():
    """The point of the carry: a window sharing 95 % of its path with the last one needs
    far fewer dual simplex iterations than from scratch (the assertion leaves a wide
    margin for other HiGHS builds), to the same optimum."""
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    n = HighsBackend.CARRY_MIN_COLUMNS
    second = window_lp(20, n)
    carried = HighsBackend()
    assert carried.solve(window_lp(0, n)).ok
    warm = carried.solve(second)
    cold_backend = HighsBackend()
    cold_backend.CARRY = False
    cold = cold_backend.solve(second)
    assert carried.carried_solves == 1 and warm.ok and cold.ok
    assert objective(second, warm.q) == pytest.approx(objective(second, cold.q), rel=1e-7)
    assert warm.iterations < 0.5 * cold.iterations, (warm.iterations, cold.iterations)


def test_planner_forget_drops_the_carried_bases():
    """After `LPPlanner.forget` (a new job, an override, a cancelled replan) the next
    window starts cold, so a job's plans do not depend on what was planned before it."""
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    from lookahead.planning.lp import LPPlanner

    planner = LPPlanner(solver="highs")
    backend = planner.backend
    assert isinstance(backend, HighsBackend)
    n = HighsBackend.CARRY_MIN_COLUMNS
    assert backend.solve(window_lp(0, n)).ok
    planner.forget()
    backend.solve(window_lp(10, n))
    assert backend.carried_solves == 0
    backend.solve(window_lp(20, n))
    assert backend.carried_solves == 1


def test_carried_windows_stay_within_one_percent_of_the_whole_job():
    """w-layers-R40-hel65-hel25-0p5mm's second window started from the first window's
    basis: at HiGHS's default primal tolerance (1e-7, a tenth of a near-rest jerk row's
    bound) its optimum put three nodes at q = 0 and the engine's job took 5.711 s against
    the whole job's 5.545 (1.030); at `PRIMAL_TOLERANCE` it is the cold start's plan."""
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    from bench.corpus import load_corpus
    from bench.corpus_bench import run_engine, run_whole

    (p,) = load_corpus("all", pattern="w-layers-R40-hel65-hel25-0p5mm")
    engine, whole = run_engine(p, "engine-lp"), run_whole(p, "lp")
    assert engine["replans"] >= 2  # carried windows, the case under test
    assert engine["fallbacks"] == 0 and engine["violations"] == 0
    assert whole["violations"] == 0
    assert engine["winding_s"] < 1.01 * whole["winding_s"]
