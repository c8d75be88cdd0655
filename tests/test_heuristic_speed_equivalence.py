"""Issue 14 (heuristic speed): the faster forms of the heuristic's inner functions give
the same results as the simple forms they replaced (kept here as references: numpy array
operations over every element, loops on numpy scalars), bit for bit on random inputs, and
a layout that cannot beat the best verified profile is not verified (the same plan), and
Ruckig segments that `reach` refuses are ones Ruckig refuses (the same plans)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from ruckig import Ruckig

from lookahead.geometry import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner, profile_build
from lookahead.planning.heuristic import planner as planner_mod
from lookahead.planning.heuristic import scurve as scurve_mod
from lookahead.planning.heuristic.path_limits import (
    BUDGET_FRACTIONS,
    BudgetShares,
    SegmentBudgets,
    _abs_max_over_points,
    _min_over_columns,
    build_grid,
    choose_segments,
    feed_limit,
    level_accelerations,
    segment_budgets,
)
from lookahead.planning.heuristic.profile_build import build_profile, state_at_s
from lookahead.planning.heuristic.reach import _brake_feed, surely_refused
from lookahead.planning.heuristic.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    cut_lists,
    feed_change_lists,
    reachable_feed,
)
from lookahead.planning.heuristic.zero_junctions import backward_pass, forward_pass

XY = AxisLimits(np.full(2, 196.0), np.full(2, 1960.0), np.full(2, 39200.0))


def _same(x: np.ndarray, y: np.ndarray) -> bool:
    return x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True)


# --- Ruckig phases --------------------------------------------------------------------

def _phases_reference(solver: SCurveSolver, s0: float, L: float, T: float, V: float) -> Phases:
    """`SCurveSolver._phases` as the numpy array operations it replaced."""
    prof = solver._traj.profiles[0][0]
    cols = [prof.t, prof.j, prof.a[:7], prof.v[:7], prof.p[:7]]
    brake = prof.brake
    if brake.duration > 0:
        cols = [list(b[:2]) + list(c) for b, c in zip(
            (brake.t, brake.j, brake.a, brake.v, brake.p), cols, strict=True)]
    arr = np.array(cols)
    arr = arr[:, arr[0] > 0]
    vel = arr[3] * (L / T)
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(arr[1] != 0.0, -arr[2] / arr[1], -1.0)
    inside = (tau > 0.0) & (tau < arr[0])
    dip = np.where(inside, arr[3] - arr[2] ** 2 / (2.0 * np.where(inside, arr[1], 1.0)),
                   arr[3]) * (L / T)
    if vel.size and min(vel.min(), dip.min()) < -1e-9 * V:
        raise SegmentInfeasibleError("motion would reverse")
    return Phases(duration=arr[0] * T, jerk=arr[1] * (L / T**3), acc=arr[2] * (L / T**2),
                  vel=vel, pos=s0 + arr[4] * L)



def test_phases_match_the_numpy_reference_on_random_segments():
    """`SCurveSolver._phases` (scalar Python) against `_phases_reference` (the numpy form)
    after random Ruckig segments and feed changes, braking ones among them (a start
    acceleration beyond the budget: Ruckig's brake phases come first)."""
    rng = np.random.default_rng(14)
    solver = SCurveSolver()
    compared = braked = 0
    for _ in range(600):
        L, V = rng.uniform(0.1, 50.0), rng.uniform(5.0, 300.0)
        A, J = rng.uniform(50.0, 3000.0), rng.uniform(1e3, 1e5)
        v0, v1 = rng.uniform(0.0, 1.2) * V, rng.uniform(0.0, 1.0) * V
        a0, a1 = rng.uniform(-2.0, 2.0) * A, rng.uniform(-0.5, 0.5) * A
        s0 = rng.uniform(-100.0, 100.0)
        try:
            if rng.uniform() < 0.3:
                got = solver.feed_change(s0, v0, a0, v1, A, J)
                T = A / J
                args = (s0, max(v0, v1, A * T) * T, T, max(v0, v1))
            else:
                got = solver.segment(s0, L, v0, a0, v1, V, A, J, a1=a1)
                args = (s0, L, L / V, V)
        except SegmentInfeasibleError:
            continue
        braked += int(solver._traj.profiles[0][0].brake.duration > 0)
        ref = _phases_reference(solver, *args)
        again = solver._phases(*args)
        for f in ("duration", "jerk", "acc", "vel", "pos"):
            assert _same(getattr(got, f), getattr(ref, f)), f
            assert _same(getattr(again, f), getattr(ref, f)), f
        compared += 1
    assert compared > 100 and braked > 5


# --- state_at_s -------------------------------------------------------------------------

def _state_at_s_reference(profile, s: np.ndarray) -> np.ndarray:
    """`state_at_s` as it was: every Newton iteration as numpy operations."""
    pp = profile.s_of_t
    c = pp.c
    h = np.diff(pp.x)
    s = np.atleast_1d(np.asarray(s, dtype=float))
    piece_start = np.maximum.accumulate(c[3])
    piece_end = ((c[0] * h + c[1]) * h + c[2]) * h + c[3]
    s = np.clip(s, piece_start[0], max(piece_end[-1], piece_start[0]))
    idx = np.clip(np.searchsorted(piece_start, s, side="right") - 1, 0, len(h) - 1)
    c0, c1, c2, c3, width = c[0, idx], c[1, idx], c[2, idx], c[3, idx], h[idx]
    target = s - c3
    rise = piece_end[idx] - c3
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(rise > 0, np.clip(target / rise, 0.0, 1.0) * width, 0.0)
        root = 2.0 * target / (c2 + np.sqrt(np.maximum(c2 * c2 + 4.0 * c1 * target, 0.0)))
        tau = np.where(np.isfinite(root) & (root >= 0.0) & (root <= width), root, tau)
    ids = None
    t, a0, a1, a2, goal, w = tau, c0, c1, c2, target, width
    lo, hi = np.zeros_like(s), width
    for _ in range(60):
        f = ((a0 * t + a1) * t + a2) * t - goal
        below = f < 0
        lo = np.where(below, t, lo)
        hi = np.where(below, hi, t)
        fp = (3.0 * a0 * t + 2.0 * a1) * t + a2
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = t - f / fp
        ok = (fp > 0) & (newton >= lo) & (newton <= hi)
        t_new = np.where(ok, newton, 0.5 * (lo + hi))
        if ids is None:
            tau = t_new
            ids = np.arange(s.size)
        else:
            tau[ids] = t_new
        left = np.abs(t_new - t) > 1e-12 * w
        if not left.any():
            break
        ids, t, a0, a1, a2, goal, w, lo, hi = (x[left] for x in (ids, t_new, a0, a1, a2, goal,
                                                                  w, lo, hi))
    v = (3.0 * c0 * tau + 2.0 * c1) * tau + c2
    a = 6.0 * c0 * tau + 2.0 * c1
    return np.stack([v, a, 6.0 * c0 * np.ones_like(tau)])


def _random_profile(rng: np.random.Generator, n: int):
    """A monotone random jerk-limited profile from rest: phases of random jerk, feed and
    acceleration kept >= 0 by ending each rise / fall before the feed would turn."""
    h, j, acc, vel, pos = [], [], [], [], []
    s = v = a = 0.0
    for _ in range(n):
        d = rng.uniform(1e-4, 0.05)
        jk = rng.choice([-1.0, 0.0, 1.0]) * rng.uniform(1e3, 1e5)
        if v + a * d + jk * d * d / 2.0 < 0.0 or (v == 0.0 and a == 0.0):
            jk = abs(jk) + 1.0  # start from rest / never reverse
        h.append(d)
        j.append(jk)
        acc.append(a)
        vel.append(v)
        pos.append(s)
        s += v * d + a * d * d / 2.0 + jk * d**3 / 6.0
        v += a * d + jk * d * d / 2.0
        a += jk * d
    return build_profile(Phases(*(np.array(x) for x in (h, j, acc, vel, pos))))


@pytest.mark.parametrize("seed", range(6))
def test_state_at_s_matches_the_all_numpy_iteration(seed, monkeypatch):
    """The scalar tail of `state_at_s` (few unconverged entries left) leaves every entry
    where the all-numpy iteration does: at random points, piece starts (bisection where
    the feed is 0) and piece ends of random profiles."""
    tails = []
    tail = profile_build._newton_tail
    monkeypatch.setattr(profile_build, "_newton_tail",
                        lambda tau, n, ids, *a: tails.append(ids.size) or tail(tau, n, ids, *a))
    rng = np.random.default_rng(seed)
    profile = _random_profile(rng, int(rng.integers(3, 60)))
    pp = profile.s_of_t
    ends = ((pp.c[0] * np.diff(pp.x) + pp.c[1]) * np.diff(pp.x) + pp.c[2]) * np.diff(pp.x) \
        + pp.c[3]
    s_max = float(ends[-1])
    s = np.concatenate([rng.uniform(-0.1 * s_max, 1.1 * s_max, 4000), pp.c[3], ends,
                        np.nextafter(pp.c[3], np.inf)])
    rng.shuffle(s)
    got = state_at_s(profile, s)
    ref = _state_at_s_reference(profile, s)
    assert tails and tails[0] > 0  # the scalar tail ran
    assert np.array_equal(got[:2], ref[:2])
    assert np.array_equal(got[2], ref[2])


# --- budgets and feed limits ------------------------------------------------------------

def _segment_budgets_reference(grid, starts, vlim, limits, shares, factor=None, v_cap=None):
    nseg = starts.size - 1
    factor = np.ones(nseg) if factor is None else factor
    seg_of_cell = np.repeat(np.arange(nseg), np.diff(starts))
    V = np.minimum.reduceat(vlim, starts[:-1])
    if v_cap is not None:
        V = np.minimum(V, v_cap)
    V = V * factor
    nb = BUDGET_FRACTIONS.size
    ncell = grid.ncells
    xs, xss, xsss = (np.abs(x[:, :nb, :]).reshape(ncell, -1)
                     for x in (grid.xs, grid.xss, grid.xsss))
    amax = np.tile(limits.amax, nb) * shares.headroom
    Vc = V[seg_of_cell][:, None]
    jmax = np.tile(limits.jmax, nb) * grid.jerk_scale[:, None] * shares.headroom
    with np.errstate(divide="ignore", invalid="ignore"):
        a_cell = np.where(xs > 0, (amax - xss * Vc**2) / xs, np.inf)
        a_cell = np.minimum(a_cell, np.where(xss > 0, shares.jerk_coupling * jmax
                                             / (3.0 * xss * Vc), np.inf))
    A = np.minimum.reduceat(_min_over_columns(a_cell), starts[:-1])
    Ac = A[seg_of_cell][:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        j_cell = np.where(xs > 0, (jmax - xsss * Vc**3 - 3.0 * xss * Vc * Ac) / xs, np.inf)
    J = np.minimum.reduceat(_min_over_columns(j_cell), starts[:-1])
    s0 = grid.edges[starts[:-1]]
    return SegmentBudgets(s0, grid.edges[starts[1:]] - s0, V, A * factor, J * factor)


def _level_accelerations_reference(grid, starts, V, J, limits, shares):
    nseg = starts.size - 1
    seg_of_cell = np.repeat(np.arange(nseg), np.diff(starts))
    nb = BUDGET_FRACTIONS.size
    ncell = grid.ncells
    xs, xss, xsss = (np.abs(x[:, :nb, :]).reshape(ncell, -1)
                     for x in (grid.xs, grid.xss, grid.xsss))
    amax = np.tile(limits.amax, nb) * shares.headroom
    jmax = np.tile(limits.jmax, nb) * grid.jerk_scale[:, None] * shares.headroom
    Vc = V[seg_of_cell][:, None]
    Jc = J[seg_of_cell][:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        a_cell = np.where(xs > 0, (amax - xss * Vc**2) / xs, np.inf)
        a_cell = np.minimum(a_cell, np.where(xss > 0, (jmax - xsss * Vc**3 - xs * Jc)
                                             / (3.0 * xss * Vc), np.inf))
    return np.minimum.reduceat(_min_over_columns(a_cell), starts[:-1])


def _feed_limit_reference(grid, limits, shares):
    nb = BUDGET_FRACTIONS.size
    xs, xss, xsss = (_abs_max_over_points(x, nb) for x in (grid.xs, grid.xss, grid.xsss))
    jmax = limits.jmax * grid.jerk_scale[:, None]
    with np.errstate(divide="ignore"):
        v_vel = shares.velocity * limits.vmax / xs
        v_acc = np.sqrt(shares.centripetal * limits.amax / xss)
        v_jerk = np.cbrt(shares.jerk_geometric * jmax / xsss)
    v = np.min(np.minimum(np.minimum(v_vel, v_acc), v_jerk), axis=1)
    return np.minimum(v, grid.c1_cap)


def _wiggly_grid():
    rng = np.random.default_rng(7)
    pts = np.cumsum(rng.normal(size=(60, 2)), axis=0) * 3.0
    pts[30] = pts[28] + 0.01  # back over itself: a near-cusp
    # pchip: C1 knots, so cells with a jerk scale below 1 and C1-knot feed caps
    path = fit_points(pts, np.ones(2), "pchip")
    grid = build_grid(path, 0.0, path.length, 0.001, XY, BudgetShares())
    assert np.any(grid.jerk_scale < 1.0)
    return grid


def test_cached_budget_terms_give_the_reference_budgets():
    """`segment_budgets`, `level_accelerations` and `feed_limit` with their arrays cached
    on the grid equal the in-place forms, for several shares and limits on one grid (the
    cache is keyed by what the terms depend on), with repair factors and feed caps."""
    grid = _wiggly_grid()
    rng = np.random.default_rng(3)
    lim2 = AxisLimits(XY.vmax, 0.5 * XY.amax, 2.0 * XY.jmax)
    for limits, shares in ((XY, BudgetShares()), (XY, BudgetShares(centripetal=0.75)),
                           (XY, BudgetShares(jerk_coupling=0.2, headroom=0.99)),
                           (lim2, BudgetShares()), (XY, BudgetShares())):
        vlim = feed_limit(grid, limits, shares)
        assert _same(vlim, _feed_limit_reference(grid, limits, shares))
        starts = choose_segments(grid, vlim, 1.1)
        nseg = starts.size - 1
        for _ in range(3):
            factor = np.where(rng.uniform(size=nseg) < 0.3, 0.85, 1.0)
            v_cap = np.where(rng.uniform(size=nseg) < 0.3, rng.uniform(1, 50, nseg), np.inf)
            got = segment_budgets(grid, starts, vlim, limits, shares, factor, v_cap)
            ref = _segment_budgets_reference(grid, starts, vlim, limits, shares, factor, v_cap)
            for f in ("s0", "L", "V", "A", "J"):
                assert _same(getattr(got, f), getattr(ref, f)), f
            V = ref.V * rng.uniform(0.3, 1.0, nseg)
            assert _same(level_accelerations(grid, starts, V, ref.J, limits, shares),
                         _level_accelerations_reference(grid, starts, V, ref.J, limits, shares))


# --- junction passes --------------------------------------------------------------------

def test_junction_passes_on_floats_match_the_numpy_scalar_loops():
    """`backward_pass` / `forward_pass` on Python floats against the loops on numpy
    scalars they replaced, on random budgets."""
    rng = np.random.default_rng(11)
    for _ in range(20):
        n = int(rng.integers(1, 40))
        b = SegmentBudgets(np.zeros(n), rng.uniform(0.01, 20.0, n), rng.uniform(1, 200, n),
                           rng.uniform(50, 3000, n), rng.uniform(1e3, 1e5, n))
        w0 = rng.uniform(0.0, 200.0, n + 1)
        slack = 1.0 - 1e-6
        ref = w0.copy()
        for k in range(n - 1, 0, -1):
            ref[k] = min(ref[k], reachable_feed(ref[k + 1], b.L[k] * slack, b.A[k], b.J[k]))
        got = backward_pass(w0.copy(), b, slack)
        assert _same(got, ref)
        for k in range(1, n):
            ref[k + 1] = min(ref[k + 1], reachable_feed(ref[k], b.L[k] * slack, b.A[k],
                                                        b.J[k]))
        forward_pass(got, b, slack)
        assert _same(got, ref)


def test_cut_rise_phases_are_float_arrays_of_the_lists():
    lists = feed_change_lists(1.0, 20.0, 0.0, 50.0, 500.0, 5000.0)
    for s_cut in (1.5, 3.0, 100.0):
        ph, _, _ = cut_lists(*lists, s_cut)
        n = ph.duration.size
        assert n >= 1
        for f, x in zip(("jerk", "acc", "vel", "pos"), lists[1:], strict=True):
            arr = getattr(ph, f)
            assert arr.dtype == float and arr.shape == (n,)
            assert np.array_equal(arr[:min(n, len(x))], np.array(x[:min(n, len(x))]))


# --- layouts that cannot win ------------------------------------------------------------

def _circle_request() -> PlanRequest:
    th = np.linspace(0.0, 2.0 * np.pi, 400)
    path = fit_points(30.0 * np.column_stack([np.cos(th), np.sin(th)]), np.ones(2), "cubic")
    return PlanRequest(path, XY, PathState(0.0), path.length, dt=0.001)


def test_a_layout_that_cannot_win_is_not_verified_and_the_plan_is_the_same(monkeypatch):
    """With a verified profile in hand, a later layout whose last round is no faster is
    dropped unverified: each profile verified after the first is faster than every one
    before it, and the plan is the one of planning with every layout verified."""
    request = _circle_request()
    verify = planner_mod.failing_segments
    plan_layout = HeuristicPlanner._plan_layout
    verified: list[float] = []

    def counted_verify(profile, *args, **kwargs):
        verified.append(profile.duration)
        return verify(profile, *args, **kwargs)

    def every_layout_verified(self, request, grid, vlim, limits, layout, rounds,
                              merge=True, beat=None):
        return plan_layout(self, request, grid, vlim, limits, layout, rounds, merge, None)

    monkeypatch.setattr(planner_mod, "failing_segments", counted_verify)
    monkeypatch.setattr(HeuristicPlanner, "_plan_layout", every_layout_verified)
    full = HeuristicPlanner().plan(request)
    n_full = len(verified)
    monkeypatch.setattr(HeuristicPlanner, "_plan_layout", plan_layout)
    verified.clear()
    planner = HeuristicPlanner()
    planner._last_layout = full.info["layout"]  # the winner first, as in a replan
    fast = planner.plan(request)
    assert len(verified) < n_full
    assert all(d < min(verified[:i]) for i, d in enumerate(verified) if i > 0)
    assert fast.info["layout"] == full.info["layout"]
    assert np.array_equal(fast.profile.s_of_t.c, full.profile.s_of_t.c)
    assert np.array_equal(fast.profile.s_of_t.x, full.profile.s_of_t.x)


# --- loss split -------------------------------------------------------------------------

def _split_by_loss_reference(edges, vlim, starts, rel_loss, abs_loss, step, max_depth=8):
    """`split.split_by_loss` as it was: every segment through the per-segment test."""
    import itertools

    length = np.diff(edges)
    inv = length / np.minimum(vlim, 1e300)
    out = [0]
    stack = [(int(a), int(b), 0) for a, b in itertools.pairwise(starts)]
    stack.reverse()
    while stack:
        a, b, depth = stack.pop()
        v = vlim[a:b]
        V = float(np.min(v))
        t_lim = float(np.sum(inv[a:b]))
        loss = float(np.sum(length[a:b])) / V - t_lim if V > 0 else 0.0
        if depth >= max_depth or b - a < 2 or not (loss > rel_loss * t_lim
                                                   and loss > abs_loss):
            out.append(b)
            continue
        low = v < step * V
        cut = np.nonzero(low[1:] != low[:-1])[0] + 1 + a
        bounds = [a, *cut.tolist(), b]
        stack.extend(reversed([(bounds[i], bounds[i + 1], depth + 1)
                               for i in range(len(bounds) - 1)]))
    return np.asarray(out, dtype=int)


def test_split_by_loss_matches_the_per_segment_loop():
    """The vectorised pre-test of `split_by_loss` (segments kept whole by a clear margin)
    gives the starts of testing every segment, on random limit curves: smooth, noisy,
    with zeros and infinities, and with losses placed right at the thresholds."""
    from lookahead.planning.heuristic.split import split_by_loss

    rng = np.random.default_rng(5)
    for trial in range(300):
        n = int(rng.integers(2, 400))
        edges = np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 2.0, n))])
        base = rng.uniform(5.0, 200.0)
        vlim = base * (1.0 + 0.3 * np.sin(np.linspace(0, rng.uniform(1, 30), n))
                       + rng.uniform(0.0, 0.2) * rng.normal(size=n) ** 2)
        if trial % 7 == 0:
            vlim[rng.integers(0, n)] = 0.0
        if trial % 11 == 0:
            vlim[rng.integers(0, n)] = np.inf
        cuts = np.unique(rng.integers(1, n, int(rng.integers(0, max(1, n // 5)))))
        starts = np.concatenate([[0], cuts, [n]])
        rel, step = float(rng.choice([0.0, 0.02, 0.1])), 1.05
        abs_loss = float(rng.choice([0.0, 1e-3, 0.05]))
        if trial % 5 == 0:  # a threshold at one segment's own loss (the tie decides)
            a, b = int(starts[0]), int(starts[1])
            length = np.diff(edges)[a:b]
            V = float(np.min(vlim[a:b]))
            if V > 0 and np.isfinite(V):
                loss = float(np.sum(length)) / V - float(np.sum(length / vlim[a:b]))
                abs_loss = loss * float(rng.choice([1.0, 1.0 - 1e-12, 1.0 - 1e-6]))
                rel = 0.0
        with np.errstate(divide="ignore"):  # a zero limit: an infinite time
            got = split_by_loss(edges, vlim, starts, rel, abs_loss, step)
            ref = _split_by_loss_reference(edges, vlim, starts, rel, abs_loss, step)
        assert np.array_equal(got, ref)


# --- Ruckig segments out of reach -------------------------------------------------------

def _raw_ruckig_ok(monkeypatch, solver: SCurveSolver, *args, a1: float) -> bool:
    """Whether Ruckig itself finds the segment (the reach test switched off)."""
    monkeypatch.setattr(scurve_mod, "surely_refused", lambda *a: False)
    try:
        solver.segment(0.0, *args, a1=a1)
        return True
    except SegmentInfeasibleError:
        return False
    finally:
        monkeypatch.undo()


def _near_reach_cases(rng: np.random.Generator, n: int):
    """Segments (L, v0, a0, v1, a1, V, A, J) whose end feed lies a relative 1e-9 .. 0.1
    on either side of the bound of `reach` (the brake, forwards or played backwards, or
    the energy bound), over wide scales; caps from the larger feed to 100x it."""
    for _ in range(n):
        A, J = 10 ** rng.uniform(1, 4), 10 ** rng.uniform(2, 6)
        v1 = 10 ** rng.uniform(-2, 3)
        a0, a1 = (rng.uniform(-1, 1) * A * rng.choice([0.0, 0.3, 1.0]) for _ in range(2))
        L = 10 ** rng.uniform(-4, 2) * max(v1, 1.0) / 10
        A = max(A, abs(a0), abs(a1))
        near = 1.0 + rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-9, -1)
        if rng.uniform() < 0.25:
            v0 = math.sqrt(max(v1 * v1 - 2.0 * A * L, 0.0)) * near
        else:
            d = _brake_feed(L, v1, -a1, A, J)
            v0 = (d if d else 0.5 * v1) * near
        if rng.uniform() < 0.5:  # the forward brake instead of the backward one
            v0, v1, a0, a1 = v1, v0, -a1, -a0
        if not v0 > 0.0:
            continue
        V = max(v0, v1) * rng.choice([1.0, 1.0 + 1e-7, rng.uniform(1, 3), rng.uniform(1, 100)])
        yield L, v0, a0, v1, a1, V, A, J


def test_the_reach_test_refuses_only_what_ruckig_refuses(monkeypatch):
    """`reach.surely_refused` never refuses a segment Ruckig finds, on segments placed
    right at its bounds (it does refuse most of those clearly beyond them), and not the
    motion that passes the jerk-limited rise in distance by braking first (a rise is no
    bound, only the energy and the brakes are)."""
    solver = SCurveSolver()
    rng = np.random.default_rng(12)
    refused = 0
    for L, v0, a0, v1, a1, V, A, J in _near_reach_cases(rng, 3000):
        if surely_refused(L, v0, a0, v1, a1, V, A, J):
            refused += 1
            assert not _raw_ruckig_ok(monkeypatch, solver, L, v0, a0, v1, V, A, J, a1=a1), \
                (L, v0, a0, v1, a1, V, A, J)
    assert refused > 500
    faster = (6.143581520780339, 4.594683863517478, 63.511081189489154, 104.18126205418301,
              120.65383111388603, 1195.759487262128, 7398.174337635069)
    assert _raw_ruckig_ok(monkeypatch, solver, *faster, a1=1159.5964758649125)
    L, v0, a0, v1, V, A, J = faster
    assert not surely_refused(L, v0, a0, v1, 1159.5964758649125, V, A, J)


def test_a_segment_out_of_reach_is_refused_without_ruckig():
    """Beyond the brake (too short to slow down), the energy bound (too short to speed
    up) or the cap, `segment` refuses without asking Ruckig."""

    class NoRuckig:
        def calculate(self, *args):
            raise AssertionError("Ruckig was asked")

    solver = SCurveSolver()
    solver._otg = NoRuckig()
    for v0, a0, v1, a1 in ((100.0, 0.0, 10.0, 0.0), (10.0, 0.0, 100.0, 0.0),
                           (100.0, 500.0, 90.0, -200.0), (50.0, 0.0, 120.0, 0.0)):
        with pytest.raises(SegmentInfeasibleError):
            solver.segment(0.0, 0.5, v0, a0, v1, 110.0, 1000.0, 1e5, a1=a1)


def _wiggly_request() -> PlanRequest:
    path = fit_points(np.cumsum(np.random.default_rng(7).normal(size=(40, 2)), axis=0) * 3.0,
                      np.ones(2), "cubic")
    return PlanRequest(path, XY, PathState(0.0), path.length, dt=0.001)


@pytest.mark.parametrize("make", [_circle_request, _wiggly_request])
def test_plans_with_the_reach_test_are_the_same(make, monkeypatch):
    """The heuristic's plans with the reach test equal those of asking Ruckig every
    segment, bit for bit (also from a moving start: the brake and the rescue paths), with
    fewer Ruckig calls."""
    calls = []
    calculate = Ruckig.calculate

    class Counted(Ruckig):
        def calculate(self, *args):
            calls.append(1)
            return calculate(self, *args)

    monkeypatch.setattr(scurve_mod, "Ruckig", Counted)
    request = make()
    half = replace(request, start=PathState(0.3 * request.s_end, 60.0, -400.0))
    fast, n_fast = [], 0
    for req in (request, half):
        fast.append(HeuristicPlanner().plan(req))
    n_fast = len(calls)
    monkeypatch.setattr(scurve_mod, "surely_refused", lambda *a: False)
    calls.clear()
    for req, got in zip((request, half), fast, strict=True):
        ref = HeuristicPlanner().plan(req)
        assert np.array_equal(got.profile.s_of_t.c, ref.profile.s_of_t.c)
        assert np.array_equal(got.profile.s_of_t.x, ref.profile.s_of_t.x)
    assert n_fast < len(calls)
