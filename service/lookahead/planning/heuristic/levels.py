"""Acceleration budgets per planning segment that depend on the feed: the centripetal
terms |x_ss| v^2 grow with the feed, so below a segment's cruise cap V more of amax is left
for path acceleration (on a circle under per-axis limits, from rest: 2-3x the budget at V).

For fractions f of V, the budgets of `path_limits.segment_budgets` with the cap lowered to
f V: A(f V) holds for every feed up to f V (the budget falls with the feed). The jerk
budget of a segment becomes the smallest over its levels (the coupling 3 |x_ss| v a may
be larger at a lower feed with its larger acceleration); each level's A is then raised to
what that jerk budget leaves to the coupling at its feed
(`path_limits.level_accelerations`). Units: path units (mm), seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.planning.heuristic.path_limits import (
    BudgetShares,
    PathGrid,
    SegmentBudgets,
    level_accelerations,
    segment_budgets,
)

#: feed levels as fractions of the cruise cap V: more levels follow A(v) more closely, for
#: one `segment_budgets` pass each, but the segment's jerk budget is the smallest over its
#: levels. Measured on the circle, the near-cusp cycloid, the B-spline corners and a
#: random XY path: 7 or 9 levels gained <= 0.6 % on the first three and lost 3 % on the
#: corners against these 4
LEVEL_FRACTIONS = (0.4, 0.65, 0.85, 1.0)


@dataclass(frozen=True)
class FeedLevels:
    """Per segment k: level top feeds tops[k] (increasing, last = V[k]) and the
    acceleration budget accs[k][m] valid for feeds up to tops[k][m]."""

    tops: list[list[float]]
    accs: list[list[float]]

    def ceiling(self, k: int, v: float) -> float:
        """The acceleration budget of segment k at feed v: that of v's level (a state
        within it is within the segment's budgets; 0 above the top)."""
        for top, acc in zip(self.tops[k], self.accs[k], strict=True):
            if v <= top:
                return acc
        return 0.0


def level_budgets(grid: PathGrid, starts: np.ndarray, vlim: np.ndarray, limits: AxisLimits,
                  shares: BudgetShares, b: SegmentBudgets, factor: np.ndarray | None = None,
                  v_cap: np.ndarray | None = None,
                  fractions: tuple[float, ...] = LEVEL_FRACTIONS
                  ) -> tuple[SegmentBudgets, FeedLevels]:
    """The feed levels of the segments of `b` (built with the same factor and v_cap), and
    `b` with each J lowered to its smallest level J."""
    base = np.minimum.reduceat(vlim, starts[:-1])
    if v_cap is not None:
        base = np.minimum(base, v_cap)
    tops, accs, J = [], [], b.J.copy()
    for f in fractions[:-1]:
        lb = segment_budgets(grid, starts, vlim, limits, shares, factor, base * f)
        tops.append(lb.V)
        # never below the budget at V (rounding at f close to 1)
        accs.append(np.maximum(lb.A, b.A))
        J = np.minimum(J, lb.J)
    scale = np.ones(b.V.size) if factor is None else factor
    for m, top in enumerate(tops):
        # the jerk the segment keeps leaves more of jmax to the coupling at a lower feed
        # than the coupling share gave it (circle: 923 -> ~1400 mm/s^2 at 0.65 V)
        free = level_accelerations(grid, starts, top, J, limits, shares) * scale
        accs[m] = np.maximum(accs[m], free)
    tops.append(b.V)
    accs.append(b.A)
    T = np.stack(tops, axis=1)
    Acc = np.stack(accs, axis=1)
    # non-increasing over the levels, as `rise.rise_levels` needs (each level's budget
    # holds for every feed below its top, so lowering one keeps it valid)
    Acc = np.minimum.accumulate(Acc, axis=1)
    return replace(b, J=J), FeedLevels(T.tolist(), Acc.tolist())
