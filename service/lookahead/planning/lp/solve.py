"""Backends for the feed LP: maximize sum(weight * q) s.t. bounds and linear rows.

Both backends see the same well-scaled problem: each variable is divided by its upper
bound (z = q / q_cap, so 0 <= z <= 1) and each row by its largest coefficient. HiGHS
solves the pure LP; OSQP solves a strongly convex proximal QP (re-centred towards the LP's
optimum) on rows renormalized to unit bounds and rewritten on finite differences of z
(`osqp_lift`), and its answer is judged on the rows themselves (`OsqpBackend`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from lookahead.planning.lp.basis_carry import CarriedBasis, map_basis, match_rows
from lookahead.planning.lp.osqp_lift import Lifted, column_range, lift_rows
from lookahead.planning.lp.rows import Rows

SOLVERS = ("osqp", "highs", "highs-milp")
#: HiGHS's default `primal_feasibility_tolerance` (restored for small LPs)
HIGHS_PRIMAL_TOLERANCE = 1e-7
#: OSQP statuses that certify infeasibility (primal, primal inaccurate): no retry
_INFEASIBLE = (3, 4)
#: ADMM iterations between rho updates (fixed: reproducible answers; 25 is OSQP's check
#: interval, measured like the time-based default on the captured windows' iterations)
ADAPTIVE_RHO_INTERVAL = 25
#: the retry's eps_abs as a fraction of the first attempt's
RETRY_EPS = 0.2
#: proximal-point re-solves stop when the LP objective gains less than this (relative),
#: and each gets at most PROX_MAX_ITER ADMM iterations (it starts at the last answer)
PROX_GAIN = 1e-4
PROX_MAX_ITER = 2000
#: the rescue attempt (`OsqpBackend`, when the first attempt and its retry are refused):
#: `bound_normalized_rows`' floor, and the limit-row excess up to which its answer goes to
#: the planner's sampled check. The first attempt's floor 1e-3 gives the rows of
#: near-stops (bounds 1e-6..1e-3 in ScaledLP units: 1159 of 1380 jerk-change rows of
#: n-butterfly's first window) a tolerance up to 1000x their bound, and ADMM left them 6x
#: outside after 20000 iterations; with 1e-6 that window converges to 0.5 % of HiGHS's
#: objective. 5e-2: c-fourier-xc-3000pts' moving-start windows stopped 2-4 % outside
#: their jerk rows in a dip to ~1e-4 of the velocity cap (no setting tried converged:
#: eps, mu, 60000 iterations, columns rescaled by the iterate); the check and its repairs
#: judge such a profile, where a refusal was a fallback for certain. Used for every
#: window, 1e-6 / 5e-2 made cam-style-R50-a45-L200 5 % slower and 3-7x the compute
#: (fast corpus, issue 13); as a rescue only, the windows that passed before are unchanged
RESCUE_FLOOR = 1e-6
RESCUE_VIOLATION = 5e-2
#: the rescue's jerk-change rows (the regularizer, not a limit) are not judged: its
#: answers stood 2-8x outside them on c-fourier-xc-3000pts; the sampled check judges the
#: profile's jerk
RESCUE_SOFT = np.inf


@dataclass
class LPOutcome:
    """The solution q (unscaled), whether the backend reported success, and its status."""

    q: np.ndarray
    ok: bool
    status: str
    iterations: int


@dataclass
class ScaledLP:
    """The problem in scaled variables z = q / q_scale, rows divided by their inf-norm."""

    cost: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    A: sp.csr_matrix
    row_lower: np.ndarray
    row_upper: np.ndarray
    q_scale: np.ndarray
    #: the variables' grid nodes s (path units), when known: OSQP maps its warm start by them
    nodes: np.ndarray | None = None

    @classmethod
    def build(
        cls, weight: np.ndarray, q_lower: np.ndarray, q_upper: np.ndarray, rows: Rows,
        nodes: np.ndarray | None = None,
    ) -> ScaledLP:
        q_scale = np.maximum(q_upper, 1e-12 * max(float(np.max(q_upper)), 1.0))
        A = rows.A.tocsr()
        # column and row scaling on the CSR arrays directly (scipy's diags products cost
        # more than the rest of the build together at these sizes)
        data = A.data * q_scale[A.indices]
        norms = np.ones(A.shape[0])
        filled = np.diff(A.indptr) > 0
        if data.size:
            peaks = np.maximum.reduceat(np.abs(data), A.indptr[:-1][filled])
            norms[filled] = np.where(peaks > 0, peaks, 1.0)
        data = data / np.repeat(norms, np.diff(A.indptr))
        A = sp.csr_matrix((data, A.indices, A.indptr), shape=A.shape)
        cost = -weight * q_scale
        cost = cost / np.max(np.abs(cost))
        return cls(
            cost,
            q_lower / q_scale,
            q_upper / q_scale,
            A,
            rows.lower / norms,
            rows.upper / norms,
            q_scale,
            None if nodes is None else np.asarray(nodes, dtype=float),
        )


def bound_normalized_rows(lp: ScaledLP, floor: float) -> tuple[sp.csc_matrix, np.ndarray,
                                                                  np.ndarray]:
    """The rows of `lp` divided by their bound magnitude max(|lower|, |upper|), floored at
    `floor` (in the coefficient-normalized units of `ScaledLP`).

    OSQP stops on absolute residuals, so a row must read "1 = the limit" for its tolerance
    to mean a fraction of the limit: after `ScaledLP`'s inf-norm scaling the jerk rows'
    bounds are ~1e-3 (their q'' coefficients ~1/h^2 dominate), and eps = 1e-3 there let
    solutions exceed a jerk limit by up to 190 % (measured). The floor keeps degenerate
    rows (bound ~0 next to rest) from blowing up the coefficients.
    """
    finite_lo = np.where(np.isfinite(lp.row_lower), np.abs(lp.row_lower), 0.0)
    finite_hi = np.where(np.isfinite(lp.row_upper), np.abs(lp.row_upper), 0.0)
    mag = np.maximum(np.maximum(finite_lo, finite_hi), floor)
    A = sp.diags(1.0 / mag) @ lp.A
    return A.tocsc(), lp.row_lower / mag, lp.row_upper / mag


def row_keys(A: sp.csr_matrix, nodes: np.ndarray) -> np.ndarray:
    """A key per row that names the same row in another window's LP: (s of the row's first
    column, how many earlier rows start on that column, its number of entries). The rows
    are stacked kind by kind and axis by axis in the same order in every window
    (`lp.rows`), so a row starting at the same node with the same rank is the same limit."""
    m = A.shape[0]
    counts = np.diff(A.indptr)
    first = np.where(counts > 0, A.indices[np.minimum(A.indptr[:-1], max(A.nnz - 1, 0))], 0)
    order = np.argsort(first, kind="stable")
    rank = np.empty(m, dtype=float)
    sorted_first = first[order]
    starts = np.r_[0, np.flatnonzero(np.diff(sorted_first)) + 1]
    run = np.repeat(starts, np.diff(np.r_[starts, m]))
    rank[order] = np.arange(m) - run
    return np.stack([nodes[first] if nodes.size else np.zeros(m), rank, counts], axis=1)


@dataclass
class _OsqpMemory:
    """The last converged solve: primal q (unscaled) and duals, keyed by node / row."""

    nodes: np.ndarray
    q: np.ndarray
    y_bounds: np.ndarray
    keys: np.ndarray
    y_rows: np.ndarray
    #: duals of the lifted difference chain (`osqp_lift`; empty without the lift)
    y_chain: np.ndarray


@dataclass(frozen=True)
class _RowSplit:
    """A problem's unit-bound rows split once per solve into the limit rows (velocity
    bounds, acceleration, jerk) and the jerk-change regularizer (`regularizer_rows`)."""

    hard: sp.csc_matrix
    hard_lo: np.ndarray
    hard_hi: np.ndarray
    soft: sp.csc_matrix
    soft_hi: np.ndarray

    @classmethod
    def of(cls, rows: sp.csc_matrix, lower: np.ndarray, upper: np.ndarray) -> _RowSplit:
        soft = regularizer_rows(rows, lower, upper)
        return cls(rows[~soft], lower[~soft], upper[~soft], rows[soft], upper[soft])


@dataclass
class _Attempt:
    """One OSQP set-up of a problem: the solver, its row split, lift and row keys, the
    number of constraint rows (all, LP rows) and variables, and whether it is the rescue."""

    solver: object
    split: _RowSplit
    lifted: Lifted | None
    keys: np.ndarray | None
    m_all: int
    rows: int
    size: int
    rescue: bool


class OsqpBackend:
    """OSQP on the scaled problem, lifted, made strongly convex, warm-started.

    The LP optimum sits at a degenerate vertex where ADMM crawls, so OSQP solves the
    proximal QP

        min  c.z + (mu / 2) ||z - z_c||^2   s.t. bounds and rows (z = q / q_scale)

    first with the centre z_c at the upper bounds, then (`prox_steps`, proximal point)
    re-centred at its own answer with mu * prox_mu, warm, until the LP objective gains less
    than PROX_GAIN: the centre at z_upper alone left a 12 % objective gap on
    c-short-xy-0p5mm (the feasible set has no greatest element once jerk rows bind).
    Rows are normalized to unit bounds (`bound_normalized_rows`) so eps is a fraction of
    each limit, and rewritten on finite differences of z (`osqp_lift`, `lift`): on the
    rows as built, no setting converged on the first jerk pass of cold windows (jerk-change
    rows ~ third differences of z bounded at ~1e-4); lifted, most windows converge. eps_rel
    is 0: OSQP's relative tolerance scales with |A x|, which the weighted chain rows make
    large (answers "solved" 10 % outside a row, measured).

    Warm start: primal AND dual of the last accepted solve. Default: when this problem has
    the last one's size (the re-solves of one window: `_unstall`, repairs). map_windows:
    also across windows, mapped onto this problem's variables by node position s
    (`ScaledLP.nodes`: a seam reuses the last grid's nodes) and onto its rows by
    `row_keys`; fresh nodes start at their lower bound with dual 0.
    On by default (issue 13: windows warm-started from the previous one's primal and
    dual). Measured on the fast corpus against the same-size-only start (which, across
    windows of equal node count, started from the last window's values by index): 0
    fallbacks either way, winding time -12 % (n-butterfly) .. +0.6 %
    (w-hel-R50-a45-sine-2mm-short), total OSQP compute ~0.65x (noisy machine). The
    iterations of a warm window are about those of a cold one: the proximal re-centring
    and the first solve's max_iter, not the start, set them.

    Acceptance (`_judge`): OSQP's answer z (clipped to the bounds) is judged on the rows
    themselves. Rows are split into the jerk-change regularizer (`regularizer_rows`) and
    the limit rows (velocity bounds, acceleration, jerk). From rest to rest (z = 0
    feasible) an answer within `pull_violation` of the limit rows is scaled onto them
    (`_pull_inside`: exactly feasible, ~excess slower). Accepted: no infeasibility
    certificate, limit rows within `accept_violation` (plans are made at the limits times
    the machine's margin, 0.98, so 1.5 % over a row stays inside the limit), jerk-change
    rows within `soft_violation` times their bound, and OSQP converged or (accept_iterate)
    stopped at max_iter. A refused answer gets one retry (`retry`) from where it stopped,
    at eps * RETRY_EPS. The planner's sampled check then judges the profile like any
    other; `LPOutcome.ok` is False otherwise. Tolerances measured on the 14 fast-corpus
    paths (bench/results/corpus_osqp_lift.json): 5e-3 / 1.0 left 3 paths with fallbacks
    (cam-style-R50-a45-L200, c-fourier-xc-3000pts, n-butterfly), 1.5e-2 / 2.0 two
    (cam-style planned with 0), inf for the jerk-change rows the same two and cam-style
    44 % slower (zig-zag jerk, repairs).

    Rescue (`rescue`): a retry refused without an infeasibility certificate gets a fresh
    set-up with the rows normalized to their own bounds down to RESCUE_FLOOR, started at
    the refused iterate; its answer is judged at RESCUE_VIOLATION with the jerk-change
    rows not judged (RESCUE_SOFT), i.e. handed to the planner's sampled check, the
    independent judge, instead of a certain fallback (fast corpus: the 3 fallbacks of
    c-fourier-xc-3000pts and n-butterfly -> 0; see RESCUE_FLOOR). Windows accepted
    before are untouched. Its duals are not kept for warm starts (other row scales).

    mu: proximal weight (scaled units). eps: OSQP eps_abs. bound_floor: see
    `bound_normalized_rows`. shrink: the inequality margin in unit-bound row units (off).
    """

    def __init__(
        self,
        mu: float = 10.0,
        eps: float = 1e-3,
        max_iter: int = 10000,
        bound_floor: float = 1e-3,
        accept_violation: float = 1.5e-2,
        shrink: float = 0.0,
        accept_iterate: bool = True,
        map_windows: bool = True,
        lift: bool = True,
        polish: bool = True,
        eps_rel: float | None = 0.0,
        chain_weight: bool = True,
        retry: bool = True,
        pull_violation: float = 5e-2,
        soft_violation: float = 2.0,
        prox_steps: int = 3,
        prox_mu: float = 0.1,
        rescue: bool = True,
    ) -> None:
        self.rescue = rescue
        self.prox_mu = prox_mu
        self.prox_steps = prox_steps
        self.soft_violation = soft_violation
        self.pull_violation = pull_violation
        self.retry = retry
        self.eps_rel = eps if eps_rel is None else eps_rel
        self.chain_weight = chain_weight
        self.lift = lift
        self.polish = polish
        self.accept_iterate = accept_iterate
        self.map_windows = map_windows
        self.mu = mu
        self.eps = eps
        self.max_iter = max_iter
        self.bound_floor = bound_floor
        self.accept_violation = accept_violation
        self.shrink = shrink
        self._memory: _OsqpMemory | None = None

    def solve(self, lp: ScaledLP, z0: np.ndarray | None = None) -> LPOutcome:
        n = lp.cost.size
        att = self._setup(lp, self.bound_floor)
        self._warm_start(att.solver, lp, att.keys, z0, att.lifted, att.m_all)
        res = att.solver.solve(raise_error=False)
        iterations = int(res.info.iter)
        z, excess, converged, ok = self._judge(res, lp, att.split)
        if not ok and self.retry and res.info.status_val not in _INFEASIBLE:
            # once more from where it stopped (OSQP keeps its iterate), to a tighter
            # tolerance and for longer: most answers refused for their row excess, and
            # most stopped by max_iter, then pass (captured fast-corpus windows)
            att.solver.update_settings(eps_abs=self.eps * RETRY_EPS, max_iter=self.max_iter)
            res = att.solver.solve(raise_error=False)
            iterations += int(res.info.iter)
            z, excess, converged, ok = self._judge(res, lp, att.split)
        if (not ok and self.rescue and res.info.status_val not in _INFEASIBLE
                and self.bound_floor > RESCUE_FLOOR):
            # rescue (see RESCUE_FLOOR): the rows rescaled to their own bounds down to
            # near-stops, from the refused iterate, judged at RESCUE_VIOLATION
            att = self._setup(lp, RESCUE_FLOOR)
            x = np.clip(np.nan_to_num(np.asarray(res.x[:n], dtype=float))
                        if res.x is not None else lp.lower, lp.lower, lp.upper)
            att.solver.warm_start(x=att.lifted.extend(x) if att.lifted is not None else x)
            res = att.solver.solve(raise_error=False)
            iterations += int(res.info.iter)
            z, excess, converged, ok = self._judge(res, lp, att.split, rescue=True)
        split, solver, N = att.split, att.solver, att.size
        if ok and self.prox_steps:
            solver.update_settings(max_iter=PROX_MAX_ITER)
        for _ in range(self.prox_steps if ok else 0):
            # proximal point: the same QP centred at the accepted answer instead of the
            # upper bounds, warm (OSQP keeps x and y). The centre at z_upper pulls the
            # QP's optimum off the LP's where the feasible set has no greatest element
            # (measured: 12 % objective gap on c-short-xy-0p5mm)
            mu = self.mu * self.prox_mu
            solver.update(q=np.r_[lp.cost - mu * z, np.zeros(N - n)],
                          Px=np.full(n, mu))
            again = solver.solve(raise_error=False)
            iterations += int(again.info.iter)
            z2, excess2, converged2, ok2 = self._judge(again, lp, split, att.rescue)
            if not ok2 or float(lp.cost @ z2) >= float(lp.cost @ z) - PROX_GAIN * abs(
                    float(lp.cost @ z)):
                if ok2 and float(lp.cost @ z2) < float(lp.cost @ z):
                    res, z, excess, converged = again, z2, excess2, converged2
                break
            res, z, excess, converged = again, z2, excess2, converged2
        if ok and res.y is not None and np.all(np.isfinite(res.y)) and not att.rescue:
            # (a rescue's duals belong to other row scales: not kept)
            y = np.asarray(res.y, dtype=float)
            m = att.rows
            nodes = lp.nodes if lp.nodes is not None else np.arange(n, dtype=float)
            self._memory = _OsqpMemory(
                nodes, z * lp.q_scale, y[:n],
                att.keys if att.keys is not None else np.empty((0, 3)), y[n:n + m],
                y[n + m:])
        status = (f"{res.info.status}{'' if converged else ' (iterate accepted)' if ok else ''}"
                  f"{' (rescue)' if att.rescue else ''}"
                  f" (worst row excess {excess:.1e} of its bound, jerk-change rows "
                  f"{_relative_excess(split.soft, split.soft_hi, z):.1e})")
        return LPOutcome(z * lp.q_scale, ok, status, iterations)

    def _setup(self, lp: ScaledLP, floor: float) -> _Attempt:
        """An OSQP solver set up on `lp`'s rows normalized with `floor`
        (`bound_normalized_rows`), lifted, with the proximal QP centred at the upper
        bounds; not warm-started."""
        import osqp

        n = lp.cost.size
        rows, row_lo, row_hi = bound_normalized_rows(lp, floor)
        # inequalities `shrink` inside (unit bounds), where the row is wide enough
        wide = (row_hi - row_lo) > 4.0 * self.shrink
        lo_in = np.where(wide & np.isfinite(row_lo), row_lo + self.shrink, row_lo)
        hi_in = np.where(wide & np.isfinite(row_hi), row_hi - self.shrink, row_hi)
        lifted = lift_rows(rows.tocsr(), chain_weight=self.chain_weight) if self.lift else None
        N = lifted.size if lifted is not None else n
        eye = sp.eye(n, N, format="csc")
        if lifted is not None:
            A = sp.vstack([eye, lifted.rows, lifted.chain], format="csc")
            zeros = np.zeros(lifted.chain.shape[0])
            lo = np.concatenate([lp.lower, lo_in, zeros])
            hi = np.concatenate([lp.upper, hi_in, zeros])
        else:
            A = sp.vstack([eye, rows], format="csc")
            lo = np.concatenate([lp.lower, lo_in])
            hi = np.concatenate([lp.upper, hi_in])
        infinity = osqp.constant("OSQP_INFTY")
        lo = np.where(np.isfinite(lo), lo, -infinity)
        hi = np.where(np.isfinite(hi), hi, infinity)
        diag = np.arange(n)
        P = sp.csc_matrix((np.full(n, self.mu), (diag, diag)), shape=(N, N))  # z only
        cost = np.r_[lp.cost - self.mu * lp.upper, np.zeros(N - n)]
        settings = {"verbose": False, "eps_abs": self.eps, "eps_rel": self.eps_rel,
                    "max_iter": self.max_iter, "polishing": self.polish, "adaptive_rho": True,
                    # rho updates every ADAPTIVE_RHO_INTERVAL iterations, not OSQP's
                    # default (a fraction of the measured setup time), which made the
                    # answers, and whole plans, depend on the machine's load
                    "adaptive_rho_interval": ADAPTIVE_RHO_INTERVAL}
        solver = osqp.OSQP()
        solver.setup(P, cost, A, lo, hi, **settings)
        keys = row_keys(rows.tocsr(), lp.nodes) if lp.nodes is not None else None
        return _Attempt(solver, _RowSplit.of(rows, row_lo, row_hi), lifted, keys,
                        A.shape[0], rows.shape[0], N, floor < self.bound_floor)

    def _judge(self, res, lp: ScaledLP, split: _RowSplit, rescue: bool = False
               ) -> tuple[np.ndarray, float, bool, bool]:
        """(z clipped to the bounds, its worst limit-row excess, converged, accepted);
        a rescue's answer is judged at RESCUE_VIOLATION and RESCUE_SOFT."""
        n = lp.cost.size
        converged = res.info.status_val in (1, 2)  # solved, solved inaccurate
        finite = res.x is not None and bool(np.all(np.isfinite(res.x)))
        z = np.asarray(res.x[:n], dtype=float) if res.x is not None else np.zeros(n)
        z = np.clip(np.nan_to_num(z), lp.lower, lp.upper)
        hard, lo_h, hi_h = split.hard, split.hard_lo, split.hard_hi
        excess = _worst_excess(hard, lo_h, hi_h, z)
        certified = res.info.status_val in _INFEASIBLE
        if (finite and not certified and excess > 0.0 and excess <= self.pull_violation
                and (converged or self.accept_iterate)):
            z, excess = _pull_inside(hard, lo_h, hi_h, lp.lower, z, excess)
        soft_limit = max(self.soft_violation, RESCUE_SOFT) if rescue else self.soft_violation
        soft_ok = (not np.isfinite(soft_limit)
                   or _relative_excess(split.soft, split.soft_hi, z) <= soft_limit)
        accept = max(self.accept_violation, RESCUE_VIOLATION) if rescue else \
            self.accept_violation
        ok = (finite and excess <= accept and soft_ok and not certified
              and (converged or self.accept_iterate))
        return z, excess, converged, ok

    def _warm_start(self, solver, lp: ScaledLP, keys: np.ndarray | None,
                    z0: np.ndarray | None, lifted: Lifted | None, m_all: int) -> None:
        """Primal and dual start (see the class docstring); with the lift, the
        differences of the primal start and the last chain duals when the sizes agree."""
        def extend(z: np.ndarray) -> np.ndarray:
            return lifted.extend(z) if lifted is not None else z

        if z0 is not None:
            solver.warm_start(x=extend(np.clip(z0, lp.lower, lp.upper)))
            return
        mem = self._memory
        if mem is None:
            return
        n = lp.cost.size
        chain = np.zeros(lifted.chain.shape[0] if lifted is not None else 0)
        m_rows = m_all - n - chain.size
        if (not self.map_windows or lp.nodes is None or keys is None
                or mem.keys.size == 0):
            if mem.q.size != n:
                return
            x = extend(np.clip(mem.q / lp.q_scale, lp.lower, lp.upper))
            if mem.y_rows.size == m_rows and mem.y_chain.size == chain.size:
                solver.warm_start(x=x, y=np.concatenate([mem.y_bounds, mem.y_rows,
                                                         mem.y_chain]))
            else:
                solver.warm_start(x=x)
            return
        # nodes: the same s to rounding (a seam reuses the node arrays themselves)
        x = lp.lower.copy()
        y_b = np.zeros(n)
        j = np.clip(np.searchsorted(mem.nodes, lp.nodes), 0, mem.nodes.size - 1)
        tol = 1e-9 * max(1.0, float(np.max(np.abs(lp.nodes))))
        hit = np.abs(mem.nodes[j] - lp.nodes) <= tol
        scale = lp.q_scale[hit]
        x[hit] = mem.q[j[hit]] / scale
        y_b[hit] = mem.y_bounds[j[hit]]
        x = np.clip(x, lp.lower, lp.upper)
        y_r = np.zeros(keys.shape[0])
        new, old = match_rows(keys, mem.keys)
        y_r[new] = mem.y_rows[old]
        solver.warm_start(x=extend(x), y=np.concatenate([y_b, y_r, chain]))


def regularizer_rows(A: sp.csc_matrix, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Rows that look like `lp.rows.jerk_change_rows`: four neighbouring columns, bounds
    symmetric and finite. (Acceleration rows are symmetric on three columns, nodal jerk
    rows one-sided on three, midpoint jerk rows one-sided on four.) They are the LP's
    regularizer against zig-zag jerk, not a machine limit; the planner's sampled check
    judges the profile either way."""
    first, last, filled = column_range(A.tocsr())
    span = np.where(filled, last - first + 1, 0)
    symmetric = np.isfinite(lower) & np.isfinite(upper) & (upper > 0) & \
        np.isclose(lower, -upper, rtol=1e-9, atol=0.0)
    return (span == 4) & symmetric


def _relative_excess(A: sp.csc_matrix, bound: np.ndarray, z: np.ndarray) -> float:
    """Largest (|A z| - bound) / bound of symmetric rows |A z| <= bound (0 when inside)."""
    if A.shape[0] == 0:
        return 0.0
    return float(max(np.max((np.abs(A @ z) - bound) / bound), 0.0))


def _pull_inside(A: sp.csc_matrix, lower: np.ndarray, upper: np.ndarray,
                 z_lower: np.ndarray, z: np.ndarray, excess: float) -> tuple[np.ndarray, float]:
    """z scaled down by the largest t <= 1 that brings every row inside its bounds, and its
    worst excess, when z = 0 meets the rows and bounds (every row's bounds hold 0, every
    variable's lower bound is 0: a job from rest to rest, the fixed nodes at q = 0). The
    rows are linear and homogeneous in q (acceleration, linearized jerk, jerk change,
    slopes at rest), so t z meets any row z exceeds once t <= bound / value; q t is ~t
    slower where it binds and no slower where rows are slack, i.e. the plan loses about
    `excess` of its speed. Else z and `excess` unchanged (the acceptance rule decides)."""
    if np.any(z_lower > 0.0) or np.any(lower > 0.0) or np.any(upper < 0.0):
        return z, excess
    Az = A @ z
    with np.errstate(divide="ignore", invalid="ignore"):
        t_hi = np.where(Az > upper, upper / Az, 1.0)
        t_lo = np.where(Az < lower, lower / Az, 1.0)
    t = float(min(np.min(t_hi, initial=1.0), np.min(t_lo, initial=1.0)))
    t = max(0.0, t * (1.0 - 1e-12))
    z = z * t
    return z, _worst_excess(A, lower, upper, z)


def _worst_excess(A: sp.csc_matrix, lower: np.ndarray, upper: np.ndarray,
                  z: np.ndarray) -> float:
    """Largest amount by which A z leaves [lower, upper] (0 when inside)."""
    if A.shape[0] == 0:
        return 0.0
    Az = A @ z
    return float(max(np.max(lower - Az), np.max(Az - upper), 0.0))


class MilpBackend:
    """HiGHS (the copy shipped inside scipy) on the scaled LP, through `scipy.optimize.milp`
    with no integer variables, cold on every call: the reference `HighsBackend` is checked
    against (tests/test_lp_solvers.py) and its A/B partner in bench/lp_engine_bench.py."""

    def solve(self, lp: ScaledLP, z0: np.ndarray | None = None) -> LPOutcome:
        from scipy.optimize import Bounds, LinearConstraint, milp

        res = milp(
            lp.cost,
            constraints=LinearConstraint(lp.A, lp.row_lower, lp.row_upper),
            bounds=Bounds(lp.lower, lp.upper),
            options={"presolve": False},
        )
        n = lp.cost.size
        ok = res.status == 0 and res.x is not None
        z = np.clip(np.asarray(res.x, dtype=float), lp.lower, lp.upper) if ok else np.zeros(n)
        iterations = int(getattr(res, "mip_node_count", 0) or 0)
        return LPOutcome(z * lp.q_scale, ok, str(res.message), iterations)


class HighsBackend:
    """HiGHS (`highspy`) on the scaled LP, one persistent model warm-started call to call.

    The planner re-solves the same rows with another objective or other bounds (`_unstall`:
    ~40 % of all solves, the stall floors) and the same grid with re-tightened rows
    (repairs). A solve whose matrix equals the loaded one only changes costs and bounds,
    and simplex restarts from the last optimal basis; one of the same shape gets the new
    matrix and the last basis as its start. Measured on the 206 LPs of c-fourier-xc-3000pts
    through the engine: 0.75 s against 1.81 s cold, same statuses, objectives equal to
    1e-6 relative (degenerate optima). A warm start that ends in anything but optimal or
    infeasible is re-run cold. Presolve off: it costs more than it saves at these sizes
    (~300 columns, ~2500 rows).

    A problem of the shape of one solved before the last (a jerk pass after the
    velocity+acceleration pass of the same grid: the retry of a grid with another jerk
    margin, the planner's fallbacks) starts from that problem's last optimal basis,
    remembered per shape (`MEMORY` shapes, off by default: see there; measured on the 44
    LPs of n-butterfly's whole job: 15700 -> 12800 simplex iterations). (The
    velocity+acceleration pass's basis with the jerk rows' slacks basic, for the first
    jerk pass, saved ~10 % of the iterations and changed two objectives by > 1e-6: not
    used.)

    A new window's first LP of a kind (rows per column: the velocity+acceleration pass,
    the jerk passes) of `CARRY_MIN_COLUMNS` columns or more starts from the last optimal
    basis of that kind, mapped onto its columns and rows by node position s
    (`basis_carry`, `CARRY`): ~3,000-6,600 dual simplex iterations cold on a fiberpath
    window, ~1,000-3,800 carried. `forget` drops the carried bases (a new job plans as
    from scratch). A problem of that size and of the loaded one's shape on other nodes is
    another window: it takes the carry, not the basis by index.
    Measured side by side on the 64 non-long corpus paths (bench/results/
    lp_quality_carry_*.json, at the primal tolerance 1e-7): engine compute summed 193.8 ->
    170.7 s, cam-fp-hel45-D60 21.2 -> 14.3 s; see `PRIMAL_TOLERANCE` for what it changed.
    (`simplex_scale_strategy` 4 in the same run: whole-job lp 271 -> 216 s, but one
    engine job +22.5 %, w-layers-R100-hel45-hoop-hel20: not used.)"""

    #: shapes (columns, rows) whose last optimal basis is kept for a later start; off (0):
    #: measured at the stop of this round, it made plans depend on what the backend solved
    #: before (a degenerate optimum reached from another basis): the replan-continuity
    #: bench's LP replans on n-butterfly refused 4 of 50 with it (p99 2.35 s), 0 of 50
    #: without (p99 47 ms), with fast-corpus winding times identical either way
    MEMORY = 0
    #: HiGHS's dual simplex edge weights: 1 = Devex. Its default (steepest edge) computes
    #: exact weights from every new start basis, one BTRAN per row (~8000 rows on the
    #: butterfly's jerk LPs), which cost more than the iterations of a warm re-solve
    #: (measured on the 44 LPs of n-butterfly's whole job: 2.3 s -> 1.35 s, the 102 of
    #: c-corners-bspline-2d 1.75 s -> 1.56 s; same statuses and objectives to 1e-6)
    EDGE_WEIGHTS = 1

    #: HiGHS's `simplex_scale_strategy`, None for its default (A/B in bench/lp_quality.py)
    SCALE_STRATEGY: int | None = None
    #: HiGHS's `primal_feasibility_tolerance` on LPs of `CARRY_MIN_COLUMNS` columns or more
    #: (its default 1e-7 below; None keeps the default everywhere). The jerk
    #: rows of nodes near rest have bounds ~1e-6 in `ScaledLP` units, so 1e-7 let a
    #: solution use a tenth of such a bound beyond it, and optima of equal objective to
    #: 1e-5 differed there: a start basis carried from another window gave three nodes
    #: at q = 0 where a cold start gave 3e-5 q_max (w-layers-R40-hel65-hel25-0p5mm's second
    #: window; its engine job +3.5 %). Measured side by side on the 64 non-long corpus
    #: paths (bench/results/lp_quality_tol_*.json, against 1e-7 without the carry): 0
    #: failures; winding median 0, whole-job lp -13 % on cam-fp-layers (110.4 -> 96.1 s),
    #: worst +0.67 % (cam-fp-hel45-D60's engine); compute summed 261 -> 233 s (lp), 195 ->
    #: 189 s (engine: the carry alone 173 s, but with the +3.5 %)
    PRIMAL_TOLERANCE: float | None = 1e-9
    #: start a new window's first LP of a kind from the last optimal basis of that kind
    #: (`basis_carry`), mapped by node position and row key, instead of from scratch
    CARRY = True
    #: the carry and `PRIMAL_TOLERANCE` apply to LPs of at least this many columns; smaller
    #: ones solve as at stop 41. There a cold solve takes a few ms, the mapping costs
    #: ~0.5 ms, and the carry changed plans more than it saved: cam-feed-w3-F20000-L500
    #: (three-drive winder, windows of 90-180 nodes), engine 4.4 -> 5.3 s side by side;
    #: the 100k-line program of that machine streamed 41.6x real time without either,
    #: 35.3x with the carry, 32.9x with both (single runs, on a machine whose noise is
    #: ~15 %). Fiberpath windows have 800-1,600 nodes.
    CARRY_MIN_COLUMNS = 400

    def __init__(self) -> None:
        self._highs = None
        self._matrix: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._nodes: np.ndarray | None = None  # the loaded problem's
        self._tolerance = HIGHS_PRIMAL_TOLERANCE  # the model's primal tolerance now
        self._bases: dict[tuple[int, int], object] = {}
        #: per kind of LP (rows per column, rounded): the last optimal solve's basis, its
        #: nodes and its matrix, converted to a `CarriedBasis` only when one is used
        self._carried: dict[int, tuple[object, np.ndarray, sp.csr_matrix]] = {}
        self.warm_solves = 0
        self.carried_solves = 0

    def _new(self):
        import highspy

        # the bare model class: `highspy.Highs()` (callbacks on) prints HiGHS's banner to
        # stdout once per process, into `lookahead plan`'s output
        h = getattr(highspy._core, "_Highs", highspy.Highs)()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("presolve", "off")
        h.setOptionValue("simplex_dual_edge_weight_strategy", self.EDGE_WEIGHTS)
        h.setOptionValue("primal_feasibility_tolerance", HIGHS_PRIMAL_TOLERANCE)
        self._tolerance = HIGHS_PRIMAL_TOLERANCE
        if self.SCALE_STRATEGY is not None:
            h.setOptionValue("simplex_scale_strategy", self.SCALE_STRATEGY)
        return h

    def solve(self, lp: ScaledLP, z0: np.ndarray | None = None) -> LPOutcome:
        import highspy

        if self._highs is None:
            self._highs = self._new()
        h = self._highs
        A = lp.A.tocsc()
        n, m = lp.cost.size, A.shape[0]
        inf = highspy.kHighsInf
        row_lo = np.where(np.isfinite(lp.row_lower), lp.row_lower, -inf)
        row_hi = np.where(np.isfinite(lp.row_upper), lp.row_upper, inf)
        last = self._matrix
        # a large problem of the last one's shape on other nodes is another window: its
        # basis by index would mean other places on the path (the carry maps them by node)
        same_shape = (last is not None and h.getNumCol() == n and h.getNumRow() == m
                      and last[0].size == A.indptr.size
                      and (not self._carries(n) or _same_nodes(self._nodes, lp.nodes)))
        same = (same_shape and np.array_equal(last[0], A.indptr)
                and np.array_equal(last[1], A.indices) and np.array_equal(last[2], A.data))
        # the loaded problem's basis, else the last of one of this shape (`MEMORY`), else
        # one carried from the last window (`CARRY`)
        basis = h.getBasis() if same_shape and h.getBasis().valid else self._bases.get((n, m))
        if basis is None and not same:
            basis = self._carry(lp)
            self.carried_solves += basis is not None
        warm = basis is not None
        if same:
            cols = np.arange(n, dtype=np.int32)
            h.changeColsCost(n, cols, lp.cost)
            h.changeColsBounds(n, cols, lp.lower, lp.upper)
            h.changeRowsBounds(m, np.arange(m, dtype=np.int32), row_lo, row_hi)
        else:
            self._pass(h, lp, A, row_lo, row_hi)
            if basis is not None:
                h.setBasis(basis)
        self._matrix = (A.indptr.copy(), A.indices.copy(), A.data.copy())
        self._nodes = lp.nodes
        tolerance = (self.PRIMAL_TOLERANCE if self.PRIMAL_TOLERANCE is not None
                     and n >= self.CARRY_MIN_COLUMNS else HIGHS_PRIMAL_TOLERANCE)
        if tolerance != self._tolerance:
            h.setOptionValue("primal_feasibility_tolerance", tolerance)
            self._tolerance = tolerance
        h.run()
        status = h.getModelStatus()
        done = (highspy.HighsModelStatus.kOptimal, highspy.HighsModelStatus.kInfeasible)
        if warm:
            self.warm_solves += 1
            if status not in done:  # a start that misled simplex: once more from scratch
                h.clearSolver()
                h.run()
                status = h.getModelStatus()
        ok = status == highspy.HighsModelStatus.kOptimal
        if ok:
            z = np.clip(np.asarray(h.getSolution().col_value, dtype=float), lp.lower, lp.upper)
            self._bases.pop((n, m), None)
            self._bases[(n, m)] = h.getBasis()
            if self.CARRY and lp.nodes is not None and lp.nodes.size == n:
                self._carried[_kind(n, m)] = (self._bases[(n, m)], lp.nodes, lp.A)
            while len(self._bases) > self.MEMORY:
                self._bases.pop(next(iter(self._bases)))
        else:
            z = np.zeros(n)
            if status not in done:  # numerical trouble: the next solve on a fresh model
                self._matrix = None
                self._bases.clear()
                self._highs = self._new()
        iterations = int(h.getInfo().simplex_iteration_count)
        return LPOutcome(z * lp.q_scale, ok, f"highs: {h.modelStatusToString(status)}",
                         iterations)

    def forget(self) -> None:
        """Drop the carried bases: the next window starts cold, as the job's first does
        (`LPPlanner.forget`: a new job, an override, a cancelled replan)."""
        self._carried.clear()

    def _carries(self, n: int) -> bool:
        """Whether an LP of n columns is started from a carried basis (`CARRY_MIN_COLUMNS`)."""
        return self.CARRY and n >= self.CARRY_MIN_COLUMNS

    def _carry(self, lp: ScaledLP):
        """An alien HiGHS basis for `lp` mapped from the last optimal solve of its kind,
        or None (no such solve, no nodes, too few rows in common)."""
        import highspy

        n, m = lp.cost.size, lp.A.shape[0]
        last = self._carried.get(_kind(n, m)) if self._carries(n) else None
        if last is None or lp.nodes is None or lp.nodes.size != n:
            return None
        basis, nodes, A = last
        carried = CarriedBasis(nodes, row_keys(sp.csr_matrix(A), nodes),
                               np.array([b.value for b in basis.col_status]),
                               np.array([b.value for b in basis.row_status]))
        codes = highspy.HighsBasisStatus
        mapped = map_basis(carried, lp.nodes, row_keys(sp.csr_matrix(lp.A), lp.nodes),
                           int(codes.kLower.value), int(codes.kBasic.value))
        if mapped is None:
            return None
        table = {int(b.value): b for b in (codes.kLower, codes.kBasic, codes.kUpper,
                                           codes.kZero, codes.kNonbasic)}
        out = highspy.HighsBasis()
        out.col_status = [table[c] for c in mapped[0].tolist()]
        out.row_status = [table[c] for c in mapped[1].tolist()]
        out.valid, out.alien = True, True
        return out

    @staticmethod
    def _pass(h, lp: ScaledLP, A: sp.csc_matrix, row_lo: np.ndarray, row_hi: np.ndarray
              ) -> None:
        import highspy

        model = highspy.HighsLp()
        model.num_col_, model.num_row_ = lp.cost.size, A.shape[0]
        model.col_cost_, model.col_lower_, model.col_upper_ = lp.cost, lp.lower, lp.upper
        model.row_lower_, model.row_upper_ = row_lo, row_hi
        model.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        model.a_matrix_.start_ = A.indptr
        model.a_matrix_.index_ = A.indices
        model.a_matrix_.value_ = A.data
        h.passModel(model)


def _same_nodes(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Whether two LPs' node arrays name the same places (both unknown counts as same)."""
    if a is None or b is None:
        return a is None and b is None
    return a is b or np.array_equal(a, b, equal_nan=True)


def _kind(n: int, m: int) -> int:
    """An LP's kind for `HighsBackend`'s carried bases: rows per column, rounded (the
    velocity+acceleration pass ~2, the jerk passes ~9-11)."""
    return round(m / max(n, 1))


def highspy_available() -> bool:
    """Whether HiGHS's own binding is installed (the `bench` extra; not a runtime
    dependency: without it "highs" is scipy's HiGHS, solved cold each time)."""
    try:
        import highspy  # noqa: F401
    except ImportError:
        return False
    return True


def make_backend(name: str) -> OsqpBackend | HighsBackend | MilpBackend:
    """"highs": the warm model when `highspy` is installed (same solver, ~24 % less CPU
    per job measured side by side), else scipy's `milp`; "highs-milp": always `milp`."""
    if name == "osqp":
        return OsqpBackend()
    if name == "highs":
        return HighsBackend() if highspy_available() else MilpBackend()
    if name == "highs-milp":
        return MilpBackend()
    raise ValueError(f"solver must be one of {SOLVERS}, got {name!r}")
