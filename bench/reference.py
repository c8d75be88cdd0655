"""The reference planner of the corpus bench: an independent, offline, fine-grid whole-job
jerk-limited LP whose sampled stream passes the finite-difference checker: a plan that
exists, so the gap between a planner's time and this one's is the planner's.

Written apart from `lookahead.planning.lp` (which it judges); it shares only the geometry
(`Path.eval_s`), the sampler's idea (positions x(s(t)) at k dt) and the checker.

Model, per stretch between corners (the machine rests at a corner, so each stretch is an
independent rest-to-rest problem), on nodes s_0 < ... < s_N:
- variables q_i = (ds/dt)^2 at the nodes, q_0 = q_N = 0; q linear in s between nodes, so
  interval i has the constant path acceleration a_i = (q_{i+1} - q_i) / (2 h_i) and the
  travel time dt_i = 2 h_i / (sqrt q_i + sqrt q_{i+1});
- velocity: q <= min_j (vmax_j / |x_s,j|)^2 (and the feed cap) at nodes and midpoints;
- acceleration of axis j at both ends of every interval: |x_ss,j q + x_s,j a_i| <= amax_j;
- jerk, in time: the axis acceleration at consecutive interval midpoints may change by at
  most jmax_j tau_i, tau_i the time between the midpoints (from rest: A = 0 before the
  first interval). tau is taken from the previous pass (below), so the rows are linear;
  q = 0 satisfies every row: the LP is always feasible.
- objective: the travel time linearized at the previous pass's q (max sum c_i q_i with
  c_i = -dT/dq_i), the first pass's from a velocity+acceleration LP.
Passes: each pass puts the nodes `node_dt` apart in time along the previous pass's profile
(dt/2 by default; coarser when a stretch would need more than `max_nodes`), takes tau
from it, solves, and stops when the time gains less than `tol` (relative): the design tau
then matches the plan's own. The plan s(t) is the C2 quintic Hermite through (t_i, s_i,
sqrt q_i, a at the node), sampled at k dt and checked at the full limits; if the checker
finds a violation the acceleration and jerk limits shrink by `SHRINK` and the last pass
is redone (reported as `shrink`), never an unchecked plan.
Solver: scipy.optimize.linprog, HiGHS (dual simplex), sparse rows scaled to unit max.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import PPoly
from scipy.optimize import linprog

from lookahead.checker import LimitChecker
from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits

#: factor on amax and jmax per failed check (trades time for a passing stream)
SHRINK = 0.97
#: first-pass (velocity + acceleration) grid: nodes per stretch
VA_NODES = 1500
#: how far (speed factor) a pass may go beyond the last (the jerk rows' conservatism):
#: RHO[0] while a pass gains > 1 %, RHO[1] while > 0.1 %, then RHO[-1]
RHO = (0.2, 0.05, 0.01)
#: grids per stretch: the first from the v+a plan, later ones along the last jerk plan
#: (a second grid gained nothing and lost up to 12 % on the fast corpus: 1)
GRIDS = 1
#: the first grid's density along the v+a plan, per node_dt (the jerk plan is slower)
VA_DENSITY = 2.0
#: most nodes per stretch. The rows see the plan only at its nodes: where consecutive
#: nodes are more than dt apart in time, the sampled jerk between them is the quintic
#: reconstruction's, not the LP's (w-issue-tube9570, one 40 s stretch: 30k nodes, 4 ms
#: apart near rest, sampled jerk 2.5 jmax even after 6 shrinks; 100k: 0 violations).
#: Trades memory and solve time (linear in nodes) for a checkable plan on long stretches.
MAX_NODES = 120_000
#: largest relative change of the curvature per interval (h |x_sss| / |x_ss|); 0.1
#: resolved the near-cusp inside a piece of c-corners-bspline-2d (its sampled jerk went
#: from 1.41 to 1.01 jmax, which the first 3 % shrink absorbs)
GEOMETRY_STEP = 0.1


@dataclass
class Stretch:
    """One rest-to-rest stretch's solution: node times t (from its start), s, q."""

    t: np.ndarray
    s: np.ndarray
    q: np.ndarray
    a_node: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def spline(self) -> PPoly:
        """s(t): the C2 quintic Hermite through (t_i, s_i, sqrt q_i, a_i)."""
        return quintic_hermite(self.t, self.s, np.sqrt(np.maximum(self.q, 0.0)),
                               self.a_node)


def quintic_hermite(t: np.ndarray, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> PPoly:
    """The piecewise quintic with value, slope and curvature p, v, a at the breakpoints t
    (vectorized; scipy's BPoly.from_derivatives loops over the intervals in Python)."""
    T = np.diff(t)
    p0, p1, v0, v1, a0, a1 = p[:-1], p[1:], v[:-1], v[1:], a[:-1], a[1:]
    dp = p1 - p0
    c3 = (20 * dp - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T**2) / (2 * T**3)
    c4 = (-30 * dp + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T**2) / (2 * T**4)
    c5 = (12 * dp - 6 * (v1 + v0) * T - (a0 - a1) * T**2) / (2 * T**5)
    return PPoly(np.stack([c5, c4, c3, a0 / 2, v0, p0]), t)


@dataclass
class ReferenceResult:
    """The reference plan: winding time (s), what it took and what the checker said."""

    winding_s: float
    stretches: list[Stretch] = field(repr=False)
    nodes: int
    grid_dt: float
    passes: int
    history: list[float]
    shrink: float
    violations: int
    peak: dict
    converged: bool
    solve_s: float

    def to_dict(self) -> dict:
        return {"winding_s": self.winding_s, "nodes": self.nodes, "grid_dt": self.grid_dt,
                "passes": self.passes, "history": self.history, "shrink": self.shrink,
                "violations": self.violations, "peak": self.peak,
                "converged": self.converged, "solve_s": self.solve_s,
                "stretches": len(self.stretches)}


@dataclass
class _Geometry:
    xs: np.ndarray  # x_s at nodes (N+1, naxes)
    xss: np.ndarray
    xs_m: np.ndarray  # at interval midpoints (N, naxes)
    vcap2: np.ndarray  # (N+1,) squared feed caps at nodes
    vcap2_m: np.ndarray  # (N,) at midpoints


def _geometry(path: Path, s: np.ndarray, lim: AxisLimits, feed_cap, lo: float,
              hi: float) -> _Geometry:
    inset = 1e-9 * max(path.length, 1.0)
    s_eval = np.clip(s, lo + inset, hi - inset)
    d = path.eval_s(s_eval, order=2)
    mid = np.clip(0.5 * (s[1:] + s[:-1]), lo + inset, hi - inset)
    dm = path.eval_s(mid, order=2)

    def cap2(xs: np.ndarray, where: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore"):
            v = np.min(lim.vmax / np.maximum(np.abs(xs), 1e-300), axis=1)
        if feed_cap is not None:
            v = np.minimum(v, feed_cap.at(where))
        return v * v

    return _Geometry(d[1], d[2], dm[1], cap2(d[1], s), cap2(dm[1], mid))


def _times(s: np.ndarray, q: np.ndarray) -> np.ndarray:
    h = np.diff(s)
    r = np.sqrt(np.maximum(q, 0.0))
    dt = 2.0 * h / np.maximum(r[1:] + r[:-1], 1e-300)
    return np.concatenate([[0.0], np.cumsum(dt)])


def _objective(s: np.ndarray, q_star: np.ndarray | None) -> np.ndarray:
    """Weights c of max c.q: the arc length of each node, times (q*)^(-1/2) (floored at
    1 % of its peak) after the first pass. A proxy for the travel time sum 2 h /
    (sqrt q_i + sqrt q_{i+1}), whose gradient (~ h q^(-3/2)) spans decades: with it the
    solver zeroed the nodes of tiny weight (stopped the plan mid-path); plain sum h q
    (first pass) underweights the slow stretches."""
    h = np.diff(s)
    w = np.zeros(s.size)
    w[1:] += h / 2
    w[:-1] += h / 2
    if q_star is None:
        return w
    r = np.sqrt(np.maximum(q_star, 0.0))
    return w / np.maximum(r, 1e-2 * max(float(np.max(r)), 1e-300))


def _solve(s: np.ndarray, geo: _Geometry, lim: AxisLimits, tau: np.ndarray | None,
           c: np.ndarray, q_max: np.ndarray | None = None) -> np.ndarray:
    """The LP on nodes s: max c.q (tau None: velocity + acceleration rows only); q_max:
    extra upper bounds on q."""
    n = s.size
    N = n - 1
    h = np.diff(s)
    qs = float(max(np.max(np.minimum(geo.vcap2, 1e30)), 1e-12))  # q = qs * y
    rows, cols, vals, rhs = [], [], [], []
    nrow = 0

    def add(parts: list[tuple[np.ndarray, np.ndarray]], bound: np.ndarray) -> None:
        """Rows sum(coef * q[idx]) <= bound over the (idx, coef) parts, scaled to unit max."""
        nonlocal nrow
        scale = np.max(np.abs(np.stack([c for _, c in parts])), axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        r = nrow + np.arange(bound.size)
        for idx, coef in parts:
            rows.append(r)
            cols.append(idx)
            vals.append(coef * qs / scale)
        rhs.append(bound / scale)
        nrow += bound.size

    ii = np.arange(N)
    # midpoint velocity caps: (q_i + q_{i+1}) / 2 <= vcap_m^2
    add([(ii, np.full(N, 0.5)), (ii + 1, np.full(N, 0.5))], np.minimum(geo.vcap2_m, 1e30))
    for j in range(lim.naxes):
        A, J = lim.amax[j], lim.jmax[j]
        # axis acceleration at interval starts (node i with a_i) and ends (node i+1, a_i):
        # x_ss q_node + x_s (q_{i+1} - q_i) / (2 h)
        for node, sign_q in ((ii, 0), (ii + 1, 1)):
            xs, xss = geo.xs[node, j], geo.xss[node, j]
            ci = -xs / (2 * h) + (xss if sign_q == 0 else 0.0)
            ck = xs / (2 * h) + (xss if sign_q == 1 else 0.0)
            for sgn in (1.0, -1.0):
                add([(ii, sgn * ci), (ii + 1, sgn * ck)], np.full(N, A))
        if tau is None:
            continue
        # midpoint acceleration of interval i: M_i = x_ssm (q_i+q_{i+1})/2 + x_sm a_i,
        # with x_ssm the mean of the ends' x_ss (linear across a fine interval)
        xsm = geo.xs_m[:, j]
        xssm = 0.5 * (geo.xss[:-1, j] + geo.xss[1:, j])
        m_lo = 0.5 * xssm - xsm / (2 * h)  # coefficient of q_i in M_i
        m_hi = 0.5 * xssm + xsm / (2 * h)  # of q_{i+1}
        # M_i - M_{i-1} for i = 1..N-1: q_{i-1}, q_i, q_{i+1}
        k = np.arange(1, N)
        c_prev = -m_lo[k - 1]
        c_mid = -m_hi[k - 1] + m_lo[k]
        c_next = m_hi[k]
        for sgn in (1.0, -1.0):
            add([(k - 1, sgn * c_prev), (k, sgn * c_mid), (k + 1, sgn * c_next)],
                J * tau[1:N])
            # from rest and to rest: |M_0| <= J tau_0, |M_{N-1}| <= J tau_N
            add([(ii[:1], sgn * m_lo[:1]), (ii[:1] + 1, sgn * m_hi[:1])], J * tau[:1])
            add([(ii[-1:], sgn * m_lo[-1:]), (ii[-1:] + 1, sgn * m_hi[-1:])], J * tau[-1:])
    A_ub = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                np.concatenate(cols))), shape=(nrow, n))
    b_ub = np.concatenate(rhs)
    upper = np.minimum(geo.vcap2, 1e30) / qs
    if q_max is not None:
        upper = np.minimum(upper, q_max / qs)
    upper[0] = upper[-1] = 0.0
    cs = c / max(float(np.max(np.abs(c))), 1e-300)
    bounds = np.column_stack([np.zeros(n), upper])
    # q = 0 is feasible, so "infeasible" is HiGHS's numerics (presolve on rows whose
    # coefficients span many decades, near-cusps): retry without presolve, then by IPM
    for method, options in (("highs-ds", {}), ("highs-ds", {"presolve": False}),
                            ("highs-ipm", {})):
        res = linprog(-cs, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method=method,
                      options=options)
        if res.status == 0 and res.x is not None:
            break
    else:
        raise RuntimeError(f"reference LP: HiGHS returned {res.message}")
    return np.clip(res.x, 0.0, upper) * qs


def _node_accel(s: np.ndarray, q: np.ndarray) -> np.ndarray:
    a = np.diff(q) / (2 * np.diff(s))
    out = np.zeros(s.size)
    out[1:-1] = 0.5 * (a[1:] + a[:-1])
    return out


def _stretch(s: np.ndarray, q: np.ndarray) -> Stretch:
    return Stretch(_times(s, q), s, q, _node_accel(s, q))


def _regrid(prev: Stretch, node_dt: float, max_nodes: int) -> tuple[np.ndarray, float]:
    """Nodes node_dt apart in time along `prev` (coarser if more than max_nodes)."""
    T = prev.duration
    step = max(node_dt, T / max_nodes)
    m = max(math.ceil(T / step), 8)
    spline = prev.spline()
    s = spline(np.linspace(0.0, T, m + 1))
    s[0], s[-1] = prev.s[0], prev.s[-1]
    s = np.maximum.accumulate(s)
    keep = np.concatenate([[True], np.diff(s) > 1e-12 * max(prev.s[-1] - prev.s[0], 1e-9)])
    keep[-1] = True
    s = s[keep]
    if s[-2] >= s[-1]:
        s = np.delete(s, -2)
    return s, T / m


def _tau(s: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Times between interval midpoints (and from/to rest: half the end intervals)."""
    dti = np.diff(_times(s, q))
    return np.concatenate([[dti[0] / 2], 0.5 * (dti[1:] + dti[:-1]), [dti[-1] / 2]])


def plan_stretch(path: Path, lo: float, hi: float, lim: AxisLimits, node_dt: float,
                 max_nodes: int, passes: int, tol: float, feed_cap=None
                 ) -> tuple[Stretch, list[float], float]:
    """Rest-to-rest over [lo, hi]: (the fastest pass's stretch, time per pass, grid dt).

    Pass k solves with upper bounds U_k on q and jerk times tau_k such that every q <= U_k
    travels each stretch in at least tau_k (tau is decreasing in q): the jerk rows are then
    conservative for the plan's own times. U_1 = the velocity+acceleration LP's q (faster
    than any jerk-limited plan), tau_1 = its times; then U_k = min(U_{k-1}, (1 + rho)^2
    q_{k-1}), tau_k = max(tau_{k-1}, tau(U_k)): the previous plan stays feasible, so no
    pass loses, and U closes in on the plan (rho = 0.2, 0.1, 0.05, 0.02, then 0.01) until a
    pass gains less than `tol`."""
    s0 = np.linspace(lo, hi, VA_NODES + 1)
    geo0 = _geometry(path, s0, lim, feed_cap, lo, hi)
    q_va = _solve(s0, geo0, lim, None, _objective(s0, None))
    prev = _stretch(s0, q_va)
    history: list[float] = []
    best: Stretch | None = None
    grid_dt = node_dt
    for g in range(GRIDS):
        # grid g: nodes node_dt apart in time along the last plan; along the v+a plan
        # (faster than any jerk plan) VA_DENSITY times denser, and jerk-limited starts
        # and stops from rest at both ends
        if best is None:
            s, grid_dt = _regrid(prev, node_dt / VA_DENSITY, max_nodes)
            grid_dt *= VA_DENSITY
            s = _densify_ends(path, s, lim, node_dt, lo, hi)
            s = _densify_geometry(path, s, lo, hi)
        else:
            s, grid_dt = _regrid(best, node_dt, max_nodes)
        geo = _geometry(path, s, lim, feed_cap, lo, hi)
        start = np.minimum(np.interp(s, prev.s, prev.q), geo.vcap2)
        rho0 = 0.0 if g == 0 else RHO[2]
        upper = np.maximum((1.0 + rho0) ** 2 * start, _floor(geo))
        upper[0] = upper[-1] = 0.0
        tau = _tau(s, upper)
        q_lin = start  # the travel time is linearized here (U is its trust region)
        t_grid = best.duration if best is not None else math.inf
        worse = 0
        for k in range(passes):
            q = _solve(s, geo, lim, tau, _objective(s, q_lin if k or g else None),
                       q_max=upper)
            cur = _stretch(s, q)
            history.append(cur.duration)
            if not math.isfinite(cur.duration):
                break
            gained = best is None or cur.duration < best.duration * (1 - tol)
            if best is None or cur.duration < best.duration:
                best = cur
            worse = 0 if gained else worse + 1
            if k >= 2 and worse >= 2:
                break
            q_lin = q
            # large steps while they pay (the first design, from the v+a plan, is far
            # too slow near rest and grows by at most 1 + rho per pass), then finer ones
            gain = (history[-2] - history[-1]) / history[-1] if len(history) > 1 else 1.0
            rho = RHO[0] if gain > 1e-2 else RHO[1] if gain > 1e-3 else RHO[-1]
            upper = np.maximum(np.minimum(upper, (1.0 + rho) ** 2 * q), _floor(geo))
            upper[0] = upper[-1] = 0.0
            tau = np.maximum(tau, _tau(s, upper))
        prev = best
        if abs(t_grid - best.duration) <= tol * best.duration:
            break
    assert best is not None
    return best, history, grid_dt


def _densify_ends(path: Path, s: np.ndarray, lim: AxisLimits, node_dt: float, lo: float,
                  hi: float) -> np.ndarray:
    """Add nodes node_dt apart in time along a jerk-limited start from rest at lo (and a
    stop at hi): s = j t^3 / 6 with the path jerk j = min_j jmax_j / |x_s,j| there, while
    they are closer than the grid's own first spacing."""
    extra = [s]
    for end, sign in ((lo, 1.0), (hi, -1.0)):
        inset = 1e-9 * max(path.length, 1.0)
        xs = path.eval_s(np.array([np.clip(end + sign * inset, lo, hi)]), order=1)[1][0]
        j = float(np.min(lim.jmax / np.maximum(np.abs(xs), 1e-300)))
        gap = (s[1] - s[0]) if sign > 0 else (s[-1] - s[-2])
        k = np.arange(1, 4000)
        ds = j * (k * node_dt) ** 3 / 6.0
        ds = ds[ds < gap]
        extra.append(end + sign * ds)
    out = np.unique(np.concatenate(extra))
    return out[(out >= lo) & (out <= hi)]


def _densify_geometry(path: Path, s: np.ndarray, lo: float, hi: float,
                      limit: float = GEOMETRY_STEP, rounds: int = 3) -> np.ndarray:
    """Split intervals over which the curvature changes fast: h max|x_sss| / max|x_ss|
    > limit (near-cusps: x_ss changes by a large factor within a node spacing, and the
    rows, taken at the nodes, would not see it)."""
    inset = 1e-9 * max(path.length, 1.0)
    for _ in range(rounds):
        d = path.eval_s(np.clip(s, lo + inset, hi - inset), order=3)
        g = np.max(np.abs(d[3]), axis=1) / np.maximum(np.max(np.abs(d[2]), axis=1), 1e-3)
        h = np.diff(s)
        parts = np.ceil(h * np.maximum(g[1:], g[:-1]) / limit).astype(int)
        if np.all(parts <= 1) or s.size > 400_000:
            break
        parts = np.minimum(parts, 16)
        extra = [s[i] + h[i] * np.arange(1, n) / n for i, n in enumerate(parts) if n > 1]
        s = np.unique(np.concatenate([s, *extra]))
    return s


def _floor(geo: _Geometry) -> np.ndarray:
    """A tiny positive floor on the upper bounds (solver zeros near rest must not pin a
    node at rest for good: two resting nodes in a row would never be left)."""
    return 1e-12 * float(np.max(np.minimum(geo.vcap2, 1e30))) * np.ones(geo.vcap2.size)


def sample_positions(path: Path, stretches: list[Stretch], dt: float,
                     chunk: int = 20000):
    """Yield position chunks (n, naxes) of the stretches played one after the other."""
    offsets = np.concatenate([[0.0], np.cumsum([st.duration for st in stretches])])
    total = offsets[-1]
    ks = np.arange(math.ceil(total / dt - 1e-9) + 1)
    splines = [st.spline() for st in stretches]
    for a in range(0, ks.size, chunk):
        t = np.minimum(ks[a:a + chunk] * dt, total)
        idx = np.clip(np.searchsorted(offsets, t, side="right") - 1, 0, len(stretches) - 1)
        s = np.empty(t.size)
        for j in np.unique(idx):
            sel = idx == j
            tl = np.clip(t[sel] - offsets[j], 0.0, stretches[j].duration)
            s[sel] = np.clip(splines[j](tl), stretches[j].s[0], stretches[j].s[-1])
        s = np.maximum.accumulate(s)
        yield path.eval_s(s, order=0)[0]


def plan_reference(path: Path, limits: AxisLimits, dt: float,
                   check_limits: AxisLimits | None = None, feed_cap=None,
                   node_dt: float | None = None, max_nodes: int = MAX_NODES, passes: int = 24,
                   tol: float = 1e-4, max_shrinks: int = 6) -> ReferenceResult:
    """Plan the whole of `path` to `limits` and check the stream at dt against
    `check_limits` (default: `limits`); shrink until it passes (see the module doc)."""
    t0 = time.perf_counter()
    check_limits = check_limits or limits
    node_dt = node_dt or dt / 2
    cuts = np.unique(np.concatenate([[0.0], np.asarray(path.corners_s(), float),
                                     [path.length]]))
    cuts = cuts[(cuts >= 0) & (cuts <= path.length)]
    spans = [(a, b) for a, b in itertools.pairwise(cuts)
             if b - a > 1e-9 * max(path.length, 1.0)]
    f = 1.0
    for attempt in range(max_shrinks + 1):
        lim = AxisLimits(limits.vmax, limits.amax * f, limits.jmax * f)
        stretches, history, grid = [], [], node_dt
        per = max_nodes
        converged = True
        for a, b in spans:
            st, hist, g = plan_stretch(path, a, b, lim, node_dt, per, passes, tol, feed_cap)
            stretches.append(st)
            history.append(hist)
            grid = max(grid, g)
            converged &= len(hist) >= 2 and abs(hist[-2] - hist[-1]) <= tol * hist[-1]
        checker = LimitChecker(check_limits, dt)
        for pos in sample_positions(path, stretches, dt):
            checker.feed(pos)
        rep = checker.report()
        if rep.ok or attempt == max_shrinks:
            break
        f *= SHRINK
    total = float(sum(st.duration for st in stretches))
    per_pass = [float(sum(h[min(i, len(h) - 1)] for h in history))
                for i in range(max(len(h) for h in history))] if history else []
    return ReferenceResult(
        winding_s=total, stretches=stretches, nodes=int(sum(st.s.size for st in stretches)),
        grid_dt=grid, passes=max((len(h) for h in history), default=0), history=per_pass,
        shrink=f, violations=rep.violations, peak=rep.peak_fraction, converged=converged,
        solve_s=time.perf_counter() - t0)
