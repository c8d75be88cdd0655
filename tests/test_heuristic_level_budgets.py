"""Feed-level acceleration budgets (`levels.level_budgets`) use the jerk a segment keeps:
below its cruise cap the coupling 3 |x_ss| v a may take what the segment's jerk budget and
the (smaller) geometric term leave of jmax, instead of its fixed share (issue 14: on a
circle the rise from rest was held at the coupling share's 923 mm/s^2 at 0.65 V where
the axis acceleration allowed ~1400; winding 1.196 -> 1.155 s on n-circle-R30)."""

from __future__ import annotations

import numpy as np

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
