"""An elastic feed LP: rows near a moving start may be exceeded, at a dominating cost.

A start state handed over by another plan (the heuristic's, one at the full limits, one
before an override) can lie outside what the LP's rows admit: they are the limits times
margins (0.98 acceleration, 0.85 jerk), linearized conservatively, with a jerk-change
regularizer, on a grid of ~6 mm; the state may need the limits themselves, a jerk the
regularizer forbids, or a turn of its acceleration within one node. Then the LP is
infeasible although the machine can continue. Here every row that touches one of the
first `zone` nodes gets two slack variables, sigma+ and sigma- >= 0, in units of the
row's bound magnitude b (scaled problem, `lp.solve.ScaledLP`):

    lower <= A z - b sigma+ + b sigma- <= upper,    cost + penalty (sigma+ + sigma-)

q = 0 beyond the zone satisfies every other row (the base problem's q = 0 argument), so
this LP is feasible whatever the start (feasible by construction), and with a penalty
above the rows' dual values (an exact penalty) its optimum has no excess whenever the
hard LP has a solution. An equality row (the start slope row: the start state itself)
costs EQUALITY_WEIGHT times more per unit, so a conflict gives way on the limit rows.
The planner's sampled check stays the judge of the result.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from lookahead.planning.lp.solve import ScaledLP

#: cost of one unit of sigma (a row exceeded by its whole bound) per LP variable: the
#: q objective is at most 1 per variable in `ScaledLP` units, so penalty n dominates any
#: gain a relaxed row could buy (measured: HiGHS solves these to the same optimum as the
#: hard LP wherever that exists)
PENALTY_PER_NODE = 10.0
#: bounds below this (in ScaledLP row units) count as this for the slack's unit
BOUND_FLOOR = 1e-6
#: the penalty on an equality row's slack (the start slope row q'(s_0)/2 = a0: the start
#: state, not a limit) is this many times a limit row's. The profile starts at a0 exactly
#: (`lp.profile`), so a slope row given way by da puts a jerk of ~da / (first interval's
#: time) at t = 0 that no row sees (measured: tube-1450, a start at 394 mm/s, +1592 mm/s^2:
#: the slope row gave 192 then 416 mm/s^2 as the repairs tightened the first nodes' jerk
#: rows, 3.8x then 7.2x jmax at t = 0). 1e3: that start then keeps its slope within
#: 1e-9; still finite, so the LP stays feasible whatever the start.
EQUALITY_WEIGHT = 1e3


def touching(A: sp.csr_matrix, zone: int) -> np.ndarray:
    """Rows of A with a nonzero coefficient on a column < zone."""
    A = A.tocsr()
    hit = (A.indices < zone) & (A.data != 0.0)
    counts = np.add.reduceat(hit.astype(int), A.indptr[:-1]) if A.nnz else np.zeros(0)
    out = np.zeros(A.shape[0], dtype=bool)
    filled = np.diff(A.indptr) > 0
    out[filled] = counts[filled] > 0
    return out


def reachable_bounds(lp: ScaledLP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """|row_lower| and |row_upper| of each row of `lp`, 0 where that side cannot bind, and
    whether some side of the row can bind. A side cannot bind when it
    is infinite, or looser than the row's reach r = sum_i |A_ri| max(|lower_i|,
    |upper_i|) (lower < -r or upper > r: no z within its bounds meets it). Why: a row
    whose coefficients are rounding noise (an axis that does not move: x_s ~ 1e-17)
    reads, after `ScaledLP`'s row scaling, as a bound of ~1e17; as a slack's unit that
    put 1.3e16 into the matrix, which HiGHS refuses (status "Empty", measured on a replan
    braking into the turnaround lock of the 100k-line program)."""
    zmax = np.maximum(np.abs(lp.lower), np.abs(lp.upper))
    zmax = np.where(np.isfinite(zmax), zmax, 0.0)  # slack columns: not in the base LP
    reach = abs(lp.A) @ zmax
    lo, hi = np.abs(lp.row_lower), np.abs(lp.row_upper)
    lo_binds = np.isfinite(lp.row_lower) & (lp.row_lower >= -reach)
    hi_binds = np.isfinite(lp.row_upper) & (lp.row_upper <= reach)
    return np.where(lo_binds, lo, 0.0), np.where(hi_binds, hi, 0.0), lo_binds | hi_binds


def elastic_lp(lp: ScaledLP, zone: int) -> tuple[ScaledLP, int]:
    """`lp` with slack columns on the rows touching its first `zone` variables; returns the
    extended LP and the number of original variables (the q part of the solution)."""
    n = lp.cost.size
    lo, hi, binds = reachable_bounds(lp)
    sel = np.nonzero(touching(lp.A, zone) & binds)[0]
    m = sel.size
    if m == 0:
        return lp, n
    b = np.maximum(np.maximum(lo, hi)[sel], BOUND_FLOOR)
    rows = np.concatenate([sel, sel])
    cols = n + np.arange(2 * m)
    vals = np.concatenate([-b, b])
    S = sp.csr_matrix((vals, (rows, cols - n)), shape=(lp.A.shape[0], 2 * m))
    A = sp.hstack([lp.A, S], format="csr")
    equal = lp.row_lower[sel] == lp.row_upper[sel]
    weight = np.where(equal, EQUALITY_WEIGHT, 1.0)
    penalty = PENALTY_PER_NODE * n * np.concatenate([weight, weight])
    nodes = None if lp.nodes is None else np.concatenate([lp.nodes, np.full(2 * m, np.nan)])
    out = ScaledLP(np.concatenate([lp.cost, penalty]),
                   np.concatenate([lp.lower, np.zeros(2 * m)]),
                   np.concatenate([lp.upper, np.full(2 * m, np.inf)]),
                   A, lp.row_lower, lp.row_upper,
                   np.concatenate([lp.q_scale, np.ones(2 * m)]), nodes)
    return out, n


def excess(lp: ScaledLP, z: np.ndarray, n: int) -> float:
    """The largest slack of a solution z of `elastic_lp` (fraction of a row's bound)."""
    return float(np.max(z[n:], initial=0.0))
