"""Backends for the feed LP: maximize sum(weight * q) s.t. bounds and linear rows.

Both backends see the same well-scaled problem: each variable is divided by its upper
bound (z = q / q_cap, so 0 <= z <= 1) and each row by its largest coefficient. HiGHS
solves the pure LP; OSQP solves a strongly convex proximal QP with the same optimum on
rows renormalized to unit bounds (`OsqpBackend`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from lookahead.planning.lp.rows import Rows

SOLVERS = ("osqp", "highs")


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

    @classmethod
    def build(
        cls, weight: np.ndarray, q_lower: np.ndarray, q_upper: np.ndarray, rows: Rows
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


class OsqpBackend:
    """OSQP on the scaled problem made strongly convex, warm-started from the last solve.

    The LP optimum sits at a degenerate vertex where ADMM crawls (20000+ iterations
    measured), so OSQP solves the proximal QP

        min  c.z + (mu / 2) ||z - z_upper||^2   s.t. bounds and rows (z = q / q_scale)

    whose optimum matches the LP's on the feed problems measured (the feasible set has a
    greatest element, which both objectives pick; objective gap <= 1.2e-4 on tube-1450).
    Rows are normalized to unit bounds (`bound_normalized_rows`) so eps is a fraction of
    each limit. The answer is clipped to the bounds and accepted only if no row is
    exceeded by more than `accept_violation` of its bound; `LPOutcome.ok` is False
    otherwise (the planner then raises PlanningError).

    mu: proximal weight (scaled units). eps: OSQP eps_abs = eps_rel. bound_floor: see
    `bound_normalized_rows`. Warm start: x and y of the last solve whenever the number of
    variables (and, for y, rows) matches: the jerk passes of one window.
    """

    def __init__(
        self,
        mu: float = 10.0,
        eps: float = 1e-3,
        max_iter: int = 20000,
        bound_floor: float = 1e-3,
        accept_violation: float = 5e-3,
    ) -> None:
        self.mu = mu
        self.eps = eps
        self.max_iter = max_iter
        self.bound_floor = bound_floor
        self.accept_violation = accept_violation
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def solve(self, lp: ScaledLP, z0: np.ndarray | None = None) -> LPOutcome:
        import osqp

        n = lp.cost.size
        rows, row_lo, row_hi = bound_normalized_rows(lp, self.bound_floor)
        A = sp.vstack([sp.identity(n, format="csc"), rows], format="csc")
        infinity = osqp.constant("OSQP_INFTY")
        lo = np.concatenate([lp.lower, row_lo])
        hi = np.concatenate([lp.upper, row_hi])
        lo = np.where(np.isfinite(lo), lo, -infinity)
        hi = np.where(np.isfinite(hi), hi, infinity)
        P = sp.diags(np.full(n, self.mu), format="csc")
        solver = osqp.OSQP()
        solver.setup(
            P, lp.cost - self.mu * lp.upper, A, lo, hi, verbose=False, eps_abs=self.eps,
            eps_rel=self.eps, max_iter=self.max_iter, polishing=True, adaptive_rho=True,
        )
        self._warm_start(solver, lp, A.shape[0], z0)
        res = solver.solve(raise_error=False)
        converged = res.info.status_val in (1, 2)  # solved, solved inaccurate
        z = np.asarray(res.x, dtype=float) if res.x is not None else np.zeros(n)
        z = np.clip(np.nan_to_num(z), lp.lower, lp.upper)
        if converged:
            self._last = (z, np.asarray(res.y, dtype=float))
        excess = _worst_excess(rows, row_lo, row_hi, z)
        ok = converged and excess <= self.accept_violation
        status = f"{res.info.status} (worst row excess {excess:.1e} of its bound)"
        return LPOutcome(z * lp.q_scale, ok, status, int(res.info.iter))

    def _warm_start(self, solver, lp: ScaledLP, m: int, z0: np.ndarray | None) -> None:
        n = lp.cost.size
        if z0 is not None:
            solver.warm_start(x=np.clip(z0, lp.lower, lp.upper))
            return
        if self._last is None or self._last[0].size != n:
            return
        x, y = self._last
        if y.size == m:
            solver.warm_start(x=np.clip(x, lp.lower, lp.upper), y=y)
        else:
            solver.warm_start(x=np.clip(x, lp.lower, lp.upper))


def _worst_excess(A: sp.csc_matrix, lower: np.ndarray, upper: np.ndarray,
                  z: np.ndarray) -> float:
    """Largest amount by which A z leaves [lower, upper] (0 when inside)."""
    if A.shape[0] == 0:
        return 0.0
    Az = A @ z
    return float(max(np.max(lower - Az), np.max(Az - upper), 0.0))


class HighsBackend:
    """HiGHS (the copy shipped inside scipy) on the scaled LP, through `scipy.optimize.milp`
    with no integer variables: unlike `linprog` it takes two-sided rows lower <= A z <= upper
    as they are (no splitting into A_ub), and with presolve off its overhead per call is
    the lowest of the scipy entry points (measured: 2.6 ms median per window LP against
    6.6 ms for linprog "highs-ds" and 3.5 ms for highspy itself)."""

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


def make_backend(name: str) -> OsqpBackend | HighsBackend:
    if name == "osqp":
        return OsqpBackend()
    if name == "highs":
        return HighsBackend()
    raise ValueError(f"solver must be one of {SOLVERS}, got {name!r}")
