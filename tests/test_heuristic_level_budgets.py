"""Feed-level acceleration budgets (`levels.level_budgets`) use the jerk a segment keeps:
below its cruise cap the coupling 3 |x_ss| v a may take what the segment's jerk budget and
the (smaller) geometric term leave of jmax, instead of its fixed share (issue 14: on a
circle the rise from rest was held at the coupling share's 923 mm/s^2 at 0.65 V where
the axis acceleration allowed ~1400; winding 1.196 -> 1.155 s on n-circle-R30)."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.geometry import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.heuristic.levels import LEVEL_FRACTIONS, level_budgets
from lookahead.planning.heuristic.path_limits import (
    BUDGET_FRACTIONS,
    BudgetShares,
    build_grid,
    choose_segments,
    feed_limit,
    segment_budgets,
)

XY = AxisLimits(np.full(2, 196.0), np.full(2, 1960.0), np.full(2, 39200.0))


def _levels(shares: BudgetShares):
    th = np.linspace(0.0, 2.0 * np.pi, 400)
    path = fit_points(30.0 * np.column_stack([np.cos(th), np.sin(th)]), np.ones(2), "cubic")
    grid = build_grid(path, 0.0, path.length, 0.001, XY, shares)
    vlim = feed_limit(grid, XY, shares)
    starts = choose_segments(grid, vlim)
    b = segment_budgets(grid, starts, vlim, XY, shares)
    b, lv = level_budgets(grid, starts, vlim, XY, shares, b, None, None, LEVEL_FRACTIONS)
    return grid, starts, b, lv


def test_level_budgets_keep_every_axis_within_its_limits():
    """At every budget point of a segment, any feed up to a level's top with |a| up to
    its budget and |j| up to the segment's J keeps each axis term within its limit."""
    shares = BudgetShares()
    grid, starts, b, lv = _levels(shares)
    nb = BUDGET_FRACTIONS.size
    for k in range(b.L.size):
        cells = slice(starts[k], starts[k + 1])
        xs, xss, xsss = (np.abs(x[cells, :nb, :]) for x in (grid.xs, grid.xss, grid.xsss))
        for top, acc in zip(lv.tops[k], lv.accs[k], strict=True):
            assert np.all(xss * top**2 + xs * acc <= XY.amax * (1 + 1e-9))
            jerk = xsss * top**3 + 3.0 * xss * top * acc + xs * b.J[k]
            assert np.all(jerk <= XY.jmax * (1 + 1e-9))


def test_lower_levels_use_more_than_the_coupling_share():
    """Below the cruise cap the budget exceeds the coupling share's cap
    share * jmax / (3 |x_ss| v) at the level's top (on a circle that cap binds)."""
    shares = BudgetShares()
    grid, starts, b, lv = _levels(shares)
    nb = BUDGET_FRACTIONS.size
    gained = []
    for k in range(b.L.size):
        xss = np.max(np.abs(grid.xss[starts[k]:starts[k + 1], :nb, :]))
        for top, acc in zip(lv.tops[k][1:-1], lv.accs[k][1:-1], strict=True):
            share_cap = shares.jerk_coupling * float(np.min(XY.jmax)) / (3.0 * xss * top)
            gained.append(acc / share_cap)
    assert min(gained) > 1.2, min(gained)


def test_a_level_rise_lands_on_the_backward_scan_faster_than_one_budget():
    """Cause (cam-fp-vonkarman, 22 % slower than the windowed LP): out of each turnaround
    the rise to the stroke's cap would overshoot the backward scan at the segment's end,
    so the chain took Ruckig's single-budget motion, holding 846 mm/s^2 (the budget at
    the cap) where the feed levels allow 2500 below 360 mm/s. `_land_level_rise` follows
    the level rise as long as Ruckig can still land it on the scan's state: the motion
    ends exactly in that state at the segment's end, keeps every feed level's budget
    until the hand-over and the single budget (or less) after it, and is faster."""
    from lookahead.planning.heuristic.path_limits import SegmentBudgets
    from lookahead.planning.heuristic.profile_build import build_profile
    from lookahead.planning.heuristic.rise import rise_levels
    from lookahead.planning.heuristic.scan import _land_level_rise
    from lookahead.planning.heuristic.scurve import SCurveSolver, end_state

    s0, L, V, A, J = 1232.3, 287.7, 557.0, 846.0, 21426.0
    tops, accs = [223.0, 362.0, 473.0, 557.0], [2559.0, 2504.0, 1845.0, 846.0]
    b = SegmentBudgets(np.array([s0]), np.array([L]), np.array([V]), np.array([A]),
                       np.array([J]))
    level = rise_levels(s0, L, 118.8, 0.0, tops, accs, J)
    assert level is not None and level[1] == pytest.approx(V)  # it reaches the cap
    target = np.array([420.0, -600.0])  # the scan, braking for what follows
    solver = SCurveSolver()
    single = solver.segment(s0, L, 118.8, 0.0, 420.0, V, A, J, a1=-600.0)
    landed = _land_level_rise(solver, b, 0, level[0], target, A, J)
    assert landed is not None
    s, v, a = end_state(landed)
    assert s == pytest.approx(s0 + L, rel=1e-9)
    assert v == pytest.approx(420.0, rel=1e-6) and a == pytest.approx(-600.0, abs=1e-3)
    assert np.sum(landed.duration) < 0.97 * np.sum(single.duration)
    prof = build_profile(landed)
    t = np.linspace(0.0, prof.duration, 4000)
    _, vv, aa, jj = prof.at(t)
    assert np.all(vv > 0.0) and np.all(np.abs(jj) <= J * (1 + 1e-9))
    ceiling = np.select([vv <= top for top in tops], accs, default=0.0)
    # the hand-over is the first sample whose acceleration exceeds the level ceiling
    # nowhere before: after it, the landing holds at most the acceleration it started at
    over = aa > ceiling * (1 + 1e-9)
    assert not over.any() or np.all(aa[np.argmax(over):] <= np.max(aa[:np.argmax(over) + 1]))
