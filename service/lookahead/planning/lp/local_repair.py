"""Local repair rounds: re-solve the LP only near the sampled check's excesses.

A repair round tightens the rows near the places where the sampled profile broke a limit
and solves a jerk pass again (`LPPlanner`'s repair loop). Solved on the whole grid, that
pass moves the feed everywhere, and on long windows the next check found new small
excesses at new places, round after round (cam-fp-hel45-D30's first window: 10-12 global
rounds, 16 -> 12 -> 13 -> 5 -> 1 -> 2 ... sampled excesses of 1.00-1.09x, each round ~75 ms
of HiGHS). A local round holds every node outside the repair zone at the last plan's q: the
profile there, already checked, stays as it was (but for the intervals beside the zone),
and only the zone can bring new excesses.

Holding a node fixes its column (lower = upper = the last q), and every row through a held
node is widened, where the tightening made the last plan break it, to contain the last
plan's activity (`held_rows`). The zone can still be infeasible (its boundary rows tie it
to the held feed beside it at the tightened limits); the caller then grows it, and at last
solves globally (`LPPlanner._repair_round`). A small zone is solved as an LP of its own
columns (`zone_rows`): as the whole LP with most columns fixed, HiGHS took as long as for a
global round (a zone of 66 of 5,635 nodes: ~115 ms). A zone over half the grid is solved as
the whole LP, in the last solve's shape, whose basis HiGHS starts from
(`LPPlanner._solve`, `ZONE_LP_MAX_SHARE`).

Written here because it is specific to this planner's grid and check: no library splits a
linearized feed LP into zones.
"""

from __future__ import annotations

import numpy as np

from lookahead.planning.lp.rows import Rows
from lookahead.planning.sampled_check import SampledRatios


def repair_zone(ratios: SampledRatios, node_times: np.ndarray, reach: int) -> np.ndarray:
    """(n,) True on the grid nodes within `reach` nodes of an interval in which a sampled
    ratio exceeds 1. node_times: (n,) the profile's time at each node (s, from its start;
    the ratios' times are on the same clock). A NaN ratio (a value not known) puts every
    node in the zone."""
    n = node_times.size
    ratio_sets = ((ratios.vel, ratios.t_vel), (ratios.acc, ratios.t_acc),
                  (ratios.jerk, ratios.t_jerk))
    if any(np.isnan(arr).any() for arr, _ in ratio_sets):
        return np.ones(n, dtype=bool)
    edges = np.zeros(n + 1, dtype=int)  # +1 where a zone starts, -1 after it ends
    for arr, t_at in ratio_sets:
        interval = np.clip(np.searchsorted(node_times, t_at[arr > 1.0]) - 1, 0, n - 2)
        np.add.at(edges, np.maximum(interval - reach, 0), 1)
        np.add.at(edges, np.minimum(interval + 1 + reach + 1, n), -1)
    return np.cumsum(edges)[:n] > 0


def held_rows(rows: Rows, q: np.ndarray, held: np.ndarray) -> Rows:
    """`rows` with the bounds of every row through a `held` node widened, where needed, to
    contain the row's activity A q at the held plan `q` (unscaled, path units^2/s^2)."""
    through = (abs(rows.A) @ held.astype(float)) > 0.0
    activity = rows.A @ q
    return Rows(rows.A, np.where(through, np.minimum(rows.lower, activity), rows.lower),
                np.where(through, np.maximum(rows.upper, activity), rows.upper))


def zone_rows(rows: Rows, held: np.ndarray, q: np.ndarray) -> Rows:
    """The rows of the LP on the free columns only (~held), the held columns' share moved
    into the bounds at their values `q`; rows on held columns only are dropped (constants,
    satisfied after `held_rows`). A zone of 66 nodes of a 5,635-node grid is then an LP of
    66 columns, not 5,635 with 5,569 fixed, which HiGHS solved no faster than the whole."""
    A = rows.A.tocsc()
    shift = A[:, held] @ q[held]
    A_zone = A[:, ~held].tocsr()
    on_zone = np.diff(A_zone.indptr) > 0
    return Rows(A_zone[on_zone], (rows.lower - shift)[on_zone], (rows.upper - shift)[on_zone])

