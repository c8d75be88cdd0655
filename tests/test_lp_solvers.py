"""The LP backends' warm starts: the persistent HiGHS model answers a sequence of re-solves
(other objective, other bounds, other matrix, an infeasible one in between) exactly as a
cold solve does, and OSQP's warm start maps primal and dual values onto the rows and nodes
that two windows share. OSQP's lifted rows are exact, its row classes and feasibility pull
do what they say, and on the LPs the planner builds for corpus paths it meets the rows and
HiGHS's objective."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import scipy.sparse as sp

from lookahead.planning.lp.basis_carry import match_rows
from lookahead.planning.lp.osqp_lift import lift_rows
from lookahead.planning.lp.rows import (
    GridGeometry,
    Rows,
    acceleration_rows,
    jerk_change_rows,
    jerk_rows,
)
from lookahead.planning.lp.solve import (
    HighsBackend,
    MilpBackend,
    OsqpBackend,
    ScaledLP,
    _pull_inside,
    _worst_excess,
    bound_normalized_rows,
    make_backend,
    regularizer_rows,
    row_keys,
)


def feed_lp(n: int, seed: int, weight: np.ndarray | None = None,
            floor: np.ndarray | None = None, step_scale: float = 1.0,
            nodes: np.ndarray | None = None) -> ScaledLP:
    """A feed-like LP: 0 <= q_i <= cap_i (q_0 = 0), |q_i+1 - q_i| <= step_i and a second
    difference row, with caps and steps varying so that several rows bind."""
    rng = np.random.default_rng(seed)
    cap = rng.uniform(50.0, 100.0, n)
    lower = np.zeros(n) if floor is None else floor.copy()
    upper = cap.copy()
    upper[0] = lower[0] = 0.0
    d1 = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n))
    d2 = sp.diags([np.ones(n - 2), -2.0 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2],
                  shape=(n - 2, n))
    step = step_scale * rng.uniform(5.0, 20.0, n - 1)
    curv = np.full(n - 2, 6.0)
    rows = Rows(sp.vstack([d1, d2]).tocsr(), np.concatenate([-step, -curv]),
                np.concatenate([step, curv]))
    return ScaledLP.build(np.ones(n) if weight is None else weight, lower, upper, rows,
                          nodes=nodes)


def objective(lp: ScaledLP, q: np.ndarray) -> float:
    return float(lp.cost @ (q / lp.q_scale))


def test_persistent_highs_matches_cold_solves_through_a_resolve_sequence():
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    n = 60
    rng = np.random.default_rng(3)
    base = feed_lp(n, 1)
    sequence = [
        base,
        feed_lp(n, 1, weight=rng.uniform(0.1, 3.0, n)),          # objective only
        feed_lp(n, 1, floor=np.full(n, 40.0)),                     # bounds: infeasible
        feed_lp(n, 1, floor=np.r_[np.zeros(30), np.full(n - 30, 5.0)]),  # bounds only
        feed_lp(n, 1, step_scale=0.5),                             # same shape, new matrix
        feed_lp(n + 7, 2),                                         # another size
        base,
    ]
    warm, cold = HighsBackend(), MilpBackend()
    statuses = []
    for lp in sequence:
        a, b = warm.solve(lp), cold.solve(lp)
        statuses.append(a.ok)
        assert a.ok == b.ok, (a.status, b.status)
        if a.ok:
            assert objective(lp, a.q) == pytest.approx(objective(lp, b.q), rel=1e-7, abs=1e-9)
            z = a.q / lp.q_scale
            assert np.all(z >= lp.lower - 1e-9) and np.all(z <= lp.upper + 1e-9)
            Az = lp.A @ z
            assert np.all(Az <= lp.row_upper + 1e-7) and np.all(Az >= lp.row_lower - 1e-7)
    assert statuses == [True, True, False, True, True, True, True]
    assert warm.warm_solves >= 4  # the re-solves did start from the last basis


def test_row_keys_name_the_same_rows_in_a_shifted_window():
    """Two windows on the same nodes shifted by 10: every row of the overlap is found, at
    the row of the other window that holds the same coefficients' pattern."""
    s = np.linspace(0.0, 59.0, 60)
    old = feed_lp(60, 1, nodes=s)
    new = feed_lp(60, 1, nodes=s + 10.0)
    k_old, k_new = row_keys(old.A, old.nodes), row_keys(new.A, new.nodes)
    i_new, i_old = match_rows(k_new, k_old)
    assert i_new.size > 0
    # matched rows start on the same node s and have as many entries
    first = lambda A, r: A.indices[A.indptr[r]]  # noqa: E731
    for a, b in zip(i_new, i_old, strict=True):
        assert new.nodes[first(new.A, a)] == old.nodes[first(old.A, b)]
        assert new.A.indptr[a + 1] - new.A.indptr[a] == old.A.indptr[b + 1] - old.A.indptr[b]
    # the overlap is nodes 10..59 of the old window: all its first-difference rows but the
    # first 10 and all second-difference rows but the first 10 are shared
    assert i_new.size == (59 - 10) + (58 - 10)


def test_osqp_warm_start_from_the_solution_itself_converges_at_once():
    """Re-solving the problem it has just solved, OSQP starts at its own primal and dual
    solution: it must converge in far fewer iterations than the cold solve did."""
    lp = feed_lp(40, 7, nodes=np.arange(40.0))
    backend = OsqpBackend(prox_steps=0)  # the ADMM stage alone (prox steps re-centre)
    cold = backend.solve(lp)
    again = backend.solve(lp)
    assert cold.ok and again.ok, (cold.status, again.status)
    assert again.iterations <= max(cold.iterations // 4, 25)
    np.testing.assert_allclose(again.q, cold.q, atol=2e-3 * float(np.max(cold.q)))


def test_osqp_answer_meets_the_rows_it_was_given():
    """With shrink, OSQP solves each inequality that far inside its bound, so the accepted
    answer meets the rows themselves to far better than `accept_violation`."""
    lp = feed_lp(40, 5)
    out = OsqpBackend(shrink=2e-3).solve(lp)
    assert out.ok, out.status
    z = out.q / lp.q_scale
    Az = lp.A @ z
    width = lp.row_upper - lp.row_lower
    assert np.all(Az <= lp.row_upper + 1e-3 * width)
    assert np.all(Az >= lp.row_lower - 1e-3 * width)


def test_osqp_mapped_warm_start_across_windows_solves_the_new_window():
    """map_windows: the second window (shifted by 10 nodes) starts from the first one's
    primal and dual values on the 50 shared nodes and still reaches HiGHS's optimum."""
    pytest.importorskip("highspy", reason="highspy is in the bench extra only")
    s = np.linspace(0.0, 59.0, 60)
    backend = OsqpBackend(map_windows=True)
    assert backend.solve(feed_lp(60, 1, nodes=s)).ok
    second = feed_lp(60, 1, nodes=s + 10.0)
    out = backend.solve(second)
    assert out.ok, out.status
    best = HighsBackend().solve(second)
    # the same objective (the `shrink` margin moves single nodes by a few %)
    assert objective(second, out.q) == pytest.approx(objective(second, best.q), rel=3e-3)
    cold = OsqpBackend().solve(second)
    assert objective(second, out.q) == pytest.approx(objective(second, cold.q), rel=1e-4)


def test_highs_without_highspy_is_scipys_milp(monkeypatch):
    """highspy is not a runtime dependency: without it "highs" solves with scipy's HiGHS."""
    monkeypatch.setitem(sys.modules, "highspy", None)  # import raises ImportError
    assert isinstance(make_backend("highs"), MilpBackend)
    assert isinstance(make_backend("highs-milp"), MilpBackend)


def test_lift_rows_rewrites_band_rows_exactly():
    """Band rows (3 and 4 columns wide) on the differences of z give A z for the lifted
    vector of any z, whose chain rows are 0; a row wider than the lift stays on z; a
    lifted vector whose differences are not those of its z breaks the chain."""
    rng = np.random.default_rng(11)
    n = 30
    parts = [sp.diags([rng.normal(size=n - 2), rng.normal(size=n - 2), rng.normal(size=n - 2)],
                      [0, 1, 2], shape=(n - 2, n)),
             sp.diags([rng.normal(size=n - 3) for _ in range(4)], [0, 1, 2, 3],
                      shape=(n - 3, n))]
    wide = np.zeros((1, n))
    wide[0, [2, 9, 20]] = rng.normal(size=3)  # spans 19 columns
    A = sp.vstack([*parts, sp.csr_matrix(wide)]).tocsr()
    lifted = lift_rows(A)
    z = rng.uniform(size=n)
    x = lifted.extend(z)
    assert x.size == lifted.size == n + (n - 1) + (n - 2) + (n - 3)
    np.testing.assert_allclose(lifted.rows @ x, A @ z, rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(lifted.chain @ x)) <= 1e-12
    # the wide row kept its coefficients on z
    np.testing.assert_array_equal(np.sort(lifted.rows.tocsr()[-1].indices), [2, 9, 20])
    bad = x.copy()
    bad[lifted.offsets[2] + 5] += 1e-3
    assert np.max(np.abs(lifted.chain @ bad)) >= 1e-3


def _helix_geometry(n: int = 80) -> GridGeometry:
    from lookahead.config import default_config
    from lookahead.geometry import fit_points

    cfg = default_config()
    t = np.linspace(0.0, 1.0, 400)
    pts = np.stack([300.0 * t, 2.0 * np.pi * 3.0 * t * 57.29577951308232], axis=1)
    path = fit_points(pts, np.asarray(cfg.machine.path_scale), "cubic")
    return GridGeometry.sample(path, np.linspace(0.0, path.length, n)), cfg.machine.limits


def test_regularizer_rows_are_exactly_the_jerk_change_rows():
    """Of the rows the planner stacks (acceleration, nodal and midpoint jerk, jerk change),
    `regularizer_rows` picks exactly the jerk-change block, after ScaledLP's scaling and
    the bound normalization OSQP sees."""
    geo, lim = _helix_geometry()
    n = geo.n_nodes
    ones = np.ones(n)
    q_star = np.full(n, 100.0)
    acc = acceleration_rows(geo, lim.amax, ones)
    jerk = jerk_rows(geo, lim.jmax, ones, q_star, 1e-6)
    change = jerk_change_rows(geo, lim.jmax, q_star, 1e-6, 0.15)
    rows = Rows.stack([acc, jerk, change], n)
    lp = ScaledLP.build(np.ones(n), np.zeros(n), np.full(n, 1e4), rows)
    A, lo, hi = bound_normalized_rows(lp, 1e-3)
    mask = regularizer_rows(A, lo, hi)
    expected = np.r_[np.zeros(acc.A.shape[0] + jerk.A.shape[0], dtype=bool),
                     np.ones(change.A.shape[0], dtype=bool)]
    assert change.A.shape[0] > 0 and jerk.A.shape[0] > 0
    np.testing.assert_array_equal(mask, expected)


def test_pull_inside_scales_onto_homogeneous_rows_only():
    """From rest to rest (z = 0 feasible) a point exceeding rows is scaled onto them; with
    a fixed moving start (a lower bound > 0) it is left alone."""
    lp = feed_lp(40, 5)
    A, lo, hi = bound_normalized_rows(lp, 1e-3)
    best = MilpBackend().solve(lp)
    z = 1.02 * best.q / lp.q_scale  # 2 % too fast: exceeds some rows
    excess = _worst_excess(A, lo, hi, z)
    assert excess > 0.0
    pulled, after = _pull_inside(A, lo, hi, lp.lower, z, excess)
    assert after <= 1e-12
    assert np.all(pulled <= z) and float(np.max(pulled / np.maximum(z, 1e-300))) > 0.97
    moving = lp.lower.copy()
    moving[0] = 0.5
    same, same_excess = _pull_inside(A, lo, hi, moving, z, excess)
    assert same is z and same_excess == excess


def _window_lps(name: str) -> list:
    """The LPs LPPlanner (HiGHS, cold) solves planning corpus path `name` as one job."""
    from bench.corpus import load_corpus

    from lookahead.planning.base import PathState, PlanRequest
    from lookahead.planning.lp import LPPlanner

    p = load_corpus("fast", pattern=name)[0]
    path, m = p.path(), p.config.machine
    request = PlanRequest(path, m.limits.scaled(p.config.planner.margin), PathState(0.0),
                          path.length, feed_cap=p.geometry().feed_cap(), dt=m.dt)
    seen = []

    class Recording(MilpBackend):
        def solve(self, lp, z0=None):
            out = super().solve(lp, z0)
            seen.append((lp, out))
            return out

    # the LPs an OSQP planner builds (its grid and jerk-change rows, `LPPlanner`)
    planner = LPPlanner(solver="highs-milp", limit_curve_grid=False, axis_jerk_change=True)
    planner.backend = Recording()
    planner.plan(request)
    return seen


@pytest.mark.parametrize("name", ["w-polar-dome-R30-a5-0p5mm", "n-circle-R30"])
def test_osqp_solves_the_planners_lps_on_corpus_paths_like_highs(name):
    """Every LP HiGHS solved for the job (the v+a pass and the jerk passes with their
    jerk-change rows, where OSQP without the lift stopped at max_iter): OSQP accepts an
    answer that meets the limit rows to its `accept_violation` and the bounds exactly, and
    its objective is within 1 % of HiGHS's optimum."""
    lps = _window_lps(name)
    assert len(lps) >= 2
    backend = OsqpBackend()
    for lp, ref in lps:
        assert ref.ok, ref.status
        out = backend.solve(lp)
        assert out.ok, out.status
        z = out.q / lp.q_scale
        assert np.all(z >= lp.lower - 1e-12) and np.all(z <= lp.upper + 1e-12)
        A, lo, hi = bound_normalized_rows(lp, backend.bound_floor)
        hard = ~regularizer_rows(A, lo, hi)
        assert _worst_excess(A[hard], lo[hard], hi[hard], z) <= backend.accept_violation
        best = float(lp.cost @ (ref.q / lp.q_scale))
        assert float(lp.cost @ z) == pytest.approx(best, rel=1e-2)


class _EnoughError(Exception):
    """Stops a recorded plan once the LPs a test needs are built."""


def test_osqp_rescue_solves_the_butterfly_first_jerk_pass():
    """n-butterfly's first jerk pass (the whole job from rest, near-stops where q is ~1e-4
    of its cap): with the rows normalized at the first attempt's floor, ADMM stopped 6x
    outside the jerk-change rows after both attempts and the engine fell back to the
    heuristic (issue 13). The rescue (rows at their own bounds down to RESCUE_FLOOR) is
    accepted: the bounds exactly, the limit rows to RESCUE_VIOLATION of their own bounds,
    and its objective near HiGHS's optimum."""
    from bench.corpus import load_corpus

    from lookahead.planning.base import PathState, PlanRequest
    from lookahead.planning.lp import LPPlanner
    from lookahead.planning.lp.solve import RESCUE_FLOOR, RESCUE_VIOLATION

    p = load_corpus("fast", pattern="n-butterfly")[0]
    path, m = p.path(), p.config.machine
    request = PlanRequest(path, m.limits.scaled(p.config.planner.margin), PathState(0.0),
                          path.length, feed_cap=p.geometry().feed_cap(), dt=m.dt)
    seen = []

    class Recording(MilpBackend):
        def solve(self, lp, z0=None):
            out = super().solve(lp, z0)
            seen.append((lp, out))
            if len(seen) == 2:  # the v+a pass, the first jerk pass
                raise _EnoughError
            return out

    planner = LPPlanner(solver="highs-milp", limit_curve_grid=False,
                        axis_jerk_change=True)  # the LPs an OSQP planner builds
    planner.backend = Recording()
    with pytest.raises(_EnoughError):
        planner.plan(request)
    lp, ref = seen[1]
    assert ref.ok, ref.status
    out = OsqpBackend().solve(lp)
    assert out.ok, out.status
    z = out.q / lp.q_scale
    assert np.all(z >= lp.lower - 1e-12) and np.all(z <= lp.upper + 1e-12)
    A, lo, hi = bound_normalized_rows(lp, RESCUE_FLOOR)
    hard = ~regularizer_rows(A, lo, hi)
    assert _worst_excess(A[hard], lo[hard], hi[hard], z) <= RESCUE_VIOLATION
    best = float(lp.cost @ (ref.q / lp.q_scale))
    assert float(lp.cost @ z) == pytest.approx(best, rel=3e-2)


def test_each_solver_gets_its_own_defaults_and_explicit_settings_win() -> None:
    from dataclasses import fields

    from lookahead.planning.lp.planner import HIGHS_DEFAULTS, OSQP_DEFAULTS, LPPlanner

    assert HIGHS_DEFAULTS != OSQP_DEFAULTS
    for solver, table in (("highs", HIGHS_DEFAULTS), ("osqp", OSQP_DEFAULTS)):
        planner = LPPlanner(solver=solver)
        for f in fields(table):
            assert getattr(planner, f.name) == getattr(table, f.name), (solver, f.name)
    explicit = LPPlanner(solver="osqp", seam_va_pass=True, seam_passes=4, local_repair=7)
    assert (explicit.seam_va_pass, explicit.seam_passes, explicit.local_repair) == (True, 4, 7)
