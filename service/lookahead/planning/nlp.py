"""The NLP feed planner (the paper's 3.1, Sencer et al.): the feed as a B-spline over s,
its control points moved by SLSQP to minimize the travel time. Offline only.

Model. q(s) = (ds/dt)^2 = w(s) r(s), r a clamped cubic B-spline over s (the variables are
its control points) and w a fixed C2 shape that vanishes like d^(4/3) at a point of rest
(d = distance to it) and is 1 farther than `sigma` away. A jerk-limited start from rest has
s ~ t^3, so q ~ d^(4/3): no polynomial q can start from rest with zero acceleration in
finite time, w r can (r stays smooth). q is linear in the control points, hence so are the
velocity rows (q <= vmax_k^2 / x'_k^2) and the acceleration rows
(|x''_k q + x'_k q'/2| <= amax_k); the jerk rows, jerk_k = sqrt(q) (x'''_k q + 3/2 x''_k q'
+ 1/2 x'_k q''), are imposed squared, q L_k^2 <= jmax_k^2 (smooth, one row per axis).
All rows are evaluated at a dense set of s (several per knot interval, graded at rests).
Travel time: T = sum 2 h / (v_i + v_i+1) over a fine s-grid (exact for q linear in s).

Windows. A feasible start plan (default: the LP's) is sampled at dt; the job is split at
points of rest and at the middle of the stretches where the start plan runs at its velocity
cap (seams, "per stroke / turnaround"). A seam's state (s, v, a) is the start plan's own
state at one of its sample times, imposed on both windows (q and q' fixed), so every window
is solved on its own with few control points, and a window that fails is replaced by the
start plan's exact piece between the same two seam times.

Start guess: the start plan's q fitted (least squares, seam states imposed), then the
control points not tied to a seam scaled down until the rows hold (bisection).

Result: per window, one quintic in t per fine-grid interval with the exact nodal state
(s, sqrt(q), q'/2) (`lp.profile`), so s(t) is C2; each window is checked by sampling at
several phases and its margins tightened and re-solved where it breaks a limit; the
stitched profile is judged by the finite-difference checker and, if it fails, the start
plan is returned instead (`info["fallback"]`).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import BSpline, PPoly
from scipy.optimize import minimize

from lookahead.checker import check_positions
from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import (
    FeedProfile,
    Planner,
    PlanningError,
    PlanRequest,
    PlanResult,
)
from lookahead.planning.lp.envelope import braking_distance, path_limits
from lookahead.planning.lp.profile import interval_durations, quintic_coefficients
from lookahead.planning.profile_ops import concatenate, slice_profile
from lookahead.planning.sampled_check import SampledRatios
from lookahead.sampling import sample_plan

_REST = 1e-9  # feeds below this (path units / s) count as rest
_DEGREE = 3


# --- the rest shape w(s) ----------------------------------------------------------------
def rest_shape(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """phi(x) = (1 - (1 - x)^3)^(4/3) for 0 <= x < 1, 1 beyond, and its first two
    derivatives: ~ (3x)^(4/3) at 0 (a constant-jerk start), C2 at x = 1."""
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
    g = 1.0 - (1.0 - x) ** 3
    g1 = 3.0 * (1.0 - x) ** 2
    g2 = -6.0 * (1.0 - x)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = g ** (4.0 / 3.0)
        phi1 = (4.0 / 3.0) * np.cbrt(g) * g1
        phi2 = (4.0 / 9.0) * g ** (-2.0 / 3.0) * g1**2 + (4.0 / 3.0) * np.cbrt(g) * g2
    return phi, phi1, np.where(g > 0, phi2, np.inf)


def rest_weight(s: np.ndarray, s0: float, s1: float, sigma: float, rest0: bool,
                rest1: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """w, dw/ds, d2w/ds2 at s: the product of the rest shapes of the rest ends of [s0, s1]."""
    w, w1, w2 = np.ones_like(s), np.zeros_like(s), np.zeros_like(s)
    if rest0:
        p, p1, p2 = rest_shape((s - s0) / sigma)
        w, w1, w2 = p, p1 / sigma, p2 / sigma**2
    if rest1:
        p, p1, p2 = rest_shape((s1 - s) / sigma)
        p1, p2 = -p1 / sigma, p2 / sigma**2
        with np.errstate(invalid="ignore"):
            w, w1, w2 = w * p, w1 * p + w * p1, w2 * p + 2.0 * w1 * p1 + w * p2
    return w, w1, w2


# --- the start plan, sampled ------------------------------------------------------------
@dataclass(frozen=True)
class SampledPlan:
    """A feasible plan sampled at t = k dt: arc length s, feed v, path acceleration a,
    and the velocity cap vcap (path units / s) at s."""

    result: PlanResult
    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    a: np.ndarray
    vcap: np.ndarray

    @classmethod
    def of(cls, result: PlanResult, path: Path, limits: AxisLimits, dt: float) -> SampledPlan:
        prof = result.profile
        t = np.arange(int(np.ceil(prof.duration / dt)) + 1) * dt
        t[-1] = prof.duration
        s, v, a, _ = prof.at(t)
        s = np.maximum.accumulate(s)
        return cls(result, t, s, np.maximum(v, 0.0), a, velocity_cap(path, limits, s))

    def q_at(self, s: np.ndarray) -> np.ndarray:
        return np.interp(s, self.s, self.v**2)


def velocity_cap(path: Path, limits: AxisLimits, s: np.ndarray) -> np.ndarray:
    """The feed the axis velocity limits allow at s: min_k vmax_k / |x'_k(s)|."""
    d1 = np.abs(path.eval_s(np.asarray(s, dtype=float), order=1)[1])
    with np.errstate(divide="ignore"):
        return np.min(limits.vmax[None, :] / d1, axis=1)


# --- windows ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Window:
    """[k0, k1] in the start plan's samples; a rest end has q = 0 built in (w), a seam end
    has the start plan's state there imposed."""

    k0: int
    k1: int
    rest0: bool
    rest1: bool


def split_windows(plan: SampledPlan, sigma: float, seam_run: float, rests: np.ndarray,
                  ) -> list[Window]:
    """Windows between rests (feed 0 in the start plan at the given s) and seams: the
    middle sample of every run of >= seam_run path units where the start plan is within
    1.5 % of its velocity cap, at least sigma away from a rest."""
    s, n = plan.s, plan.s.size
    at_rest = plan.v <= _REST
    rest_idx = [0] + [int(np.searchsorted(s, r)) for r in rests] + [n - 1]
    plateau = plan.v >= 0.985 * plan.vcap
    cuts: list[tuple[int, bool]] = [(0, bool(at_rest[0]))]
    for lo, hi in itertools.pairwise(rest_idx):
        if hi - lo < 2:
            continue
        run_start = None
        for k in range(lo, hi + 1):
            inside = plateau[k] and k < hi
            if inside and run_start is None:
                run_start = k
            elif not inside and run_start is not None:
                mid = (run_start + k - 1) // 2
                far = min(s[mid] - s[lo], s[hi] - s[mid]) >= sigma
                if s[k - 1] - s[run_start] >= seam_run and far:
                    cuts.append((mid, False))
                run_start = None
        if hi != n - 1:
            cuts.append((hi, True))
    cuts.append((n - 1, bool(at_rest[-1])))
    return [Window(k0, k1, r0, r1) for (k0, r0), (k1, r1) in itertools.pairwise(cuts) if k1 > k0]


def knot_vector(s: np.ndarray, v: np.ndarray, plateau: np.ndarray, knot_time: float,
                min_knot: float, max_knot: float, growth: float = 0.5) -> np.ndarray:
    """Clamped cubic knots over [s[0], s[-1]]: spacing v * knot_time (clipped to
    [min_knot, max_knot]) where the start plan changes its feed, max_knot where it runs at
    its cap, and growing by at most `growth` per path unit in between."""
    want = np.where(plateau, max_knot, np.clip(v * knot_time, min_knot, max_knot))
    # hand-written: a two-sweep distance transform (no library does this 1-D min-plus pass)
    for order in (range(1, want.size), range(want.size - 2, -1, -1)):
        for i in order:
            j = i - 1 if order.step == 1 else i + 1
            want[i] = min(want[i], want[j] + growth * abs(s[i] - s[j]))
    density = np.concatenate([[0.0], np.cumsum(np.diff(s) / (0.5 * (want[1:] + want[:-1])))])
    n_int = max(round(density[-1]), 1)
    inner = np.interp(np.arange(1, n_int) * density[-1] / n_int, density, s)
    return np.concatenate([[s[0]] * (_DEGREE + 1), inner, [s[-1]] * (_DEGREE + 1)])


def graded_points(s0: float, s1: float, step: float, rest0: bool, rest1: bool,
                  sigma: float) -> np.ndarray:
    """Points from s0 to s1 every ~step, plus geometric grading towards rest ends (where
    q ~ d^(4/3) changes fastest)."""
    pts = [np.linspace(s0, s1, max(int(np.ceil((s1 - s0) / step)), 2) + 1)]
    grade = np.geomspace(1e-5, 1.0, 30) * min(sigma, 0.5 * (s1 - s0))
    if rest0:
        pts.append(s0 + grade)
    if rest1:
        pts.append(s1 - grade)
    return np.unique(np.concatenate(pts))


# --- one window's problem ---------------------------------------------------------------
@dataclass(frozen=True)
class Margins:
    """Fractions of vmax, amax, jmax the optimizer plans to (the checker judges at 1)."""

    vel: float = 0.999
    acc: float = 0.99
    jerk: float = 0.97


@dataclass
class PointMargins:
    """Per constraint point s: the fractions of vmax, amax, jmax planned to there."""

    s: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    jerk: np.ndarray

    @classmethod
    def uniform(cls, s: np.ndarray, m: Margins) -> PointMargins:
        return cls(s, *(np.full(s.size, f) for f in (m.vel, m.acc, m.jerk)))

    def tighten(self, peaks: SampledRatios, s_at, radius: float) -> None:
        """Scale the margins down within `radius` of every place a limit was exceeded."""
        for kind in ("vel", "acc", "jerk"):
            ratio, t_at = getattr(peaks, kind), getattr(peaks, "t_" + kind)
            bad = ratio > 1.0
            if not np.any(bad):
                continue
            arr = getattr(self, kind)
            for s_bad, r in zip(s_at(t_at[bad]), ratio[bad], strict=True):
                near = np.abs(self.s - s_bad) <= radius
                arr[near] = np.minimum(arr[near], arr[near] * min(0.995, 0.99 / r))


@dataclass
class FeedSpline:
    """q(s) = w(s) B(s) c on one window: the basis, the rest shape, the seam states."""

    knots: np.ndarray
    window: Window
    sigma: float
    s0: float
    s1: float

    @property
    def n_ctrl(self) -> int:
        return self.knots.size - _DEGREE - 1

    def operators(self, x: np.ndarray, order: int) -> list[np.ndarray]:
        """[Q0, Q1, ...]: q^(n)(x) = Q_n c, dense (len(x), n_ctrl), n = 0..order."""
        eye = BSpline(self.knots, np.eye(self.n_ctrl), _DEGREE, extrapolate=False)
        x = np.clip(x, self.s0, self.s1)
        B = [np.nan_to_num(eye(x, nu)) for nu in range(order + 1)]
        w, w1, w2 = rest_weight(x, self.s0, self.s1, self.sigma, self.window.rest0,
                                self.window.rest1)
        ops = [w[:, None] * B[0]]
        if order >= 1:
            ops.append(w1[:, None] * B[0] + w[:, None] * B[1])
        if order >= 2:
            ops.append(w2[:, None] * B[0] + 2.0 * w1[:, None] * B[1] + w[:, None] * B[2])
        return ops


@dataclass
class WindowProblem:
    """Rows and objective of one window in scaled variables z = c / qs."""

    spline: FeedSpline
    qs: float
    vel_rhs: np.ndarray
    vel_op: np.ndarray
    acc_op: np.ndarray  # rows already divided by the margin times amax
    jerk_q: np.ndarray  # Q0 at the jerk points (scaled)
    jerk_l: list[np.ndarray]  # per axis: kappa * L operator
    obj_h: np.ndarray
    obj_op: np.ndarray
    eq_op: np.ndarray
    eq_rhs: np.ndarray
    t_ref: float = 1.0

    @classmethod
    def build(cls, spline: FeedSpline, path: Path, limits: AxisLimits, margins: PointMargins,
              vcap_fn, seam0: tuple[float, float] | None, seam1: tuple[float, float] | None,
              obj_points: np.ndarray) -> WindowProblem:
        win = spline.window
        keep = np.ones(margins.s.size, dtype=bool)
        if win.rest0:
            keep &= margins.s > spline.s0
        if win.rest1:
            keep &= margins.s < spline.s1
        rows_at = margins.s[keep]
        m_vel, m_acc, m_jerk = margins.vel[keep], margins.acc[keep], margins.jerk[keep]
        Q0, Q1, Q2 = spline.operators(rows_at, 2)
        d = path.eval_s(rows_at, order=3)
        vcap2 = np.minimum((m_vel * vcap_fn(rows_at)) ** 2, 1e300)
        qs = float(np.max(np.minimum(vcap2, 4.0 * np.median(vcap2))))
        acc, jl = [], []
        for k in range(d[1].shape[1]):
            acc.append((d[2][:, k, None] * Q0 + 0.5 * d[1][:, k, None] * Q1)
                       * (qs / limits.amax[k] / m_acc)[:, None])
            kappa = qs**1.5 / (m_jerk * limits.jmax[k])
            jl.append(kappa[:, None] * (d[3][:, k, None] * Q0 + 1.5 * d[2][:, k, None] * Q1
                               + 0.5 * d[1][:, k, None] * Q2))
        eq_op, eq_rhs = [], []
        for seam, x in ((seam0, spline.s0), (seam1, spline.s1)):
            if seam is not None:
                E0, E1 = spline.operators(np.array([x]), 1)
                norm = max(seam[0], qs * 1e-3)
                eq_op += [E0[0] * qs / norm, E1[0] * qs / norm]
                eq_rhs += [seam[0] / norm, seam[1] / norm]
        (O0,) = spline.operators(obj_points, 0)
        n = spline.n_ctrl
        return cls(spline, qs, np.minimum(vcap2 / qs, 1e6), Q0, np.vstack(acc), Q0, jl,
                   np.diff(obj_points), O0 * qs,
                   np.array(eq_op).reshape(-1, n), np.array(eq_rhs))

    # objective: travel time (s) over t_ref
    def time(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        q = self.obj_op @ z
        v = np.sqrt(np.maximum(q, 0.0))
        vs = np.maximum(v[:-1] + v[1:], 1e-12)
        T = float(np.sum(2.0 * self.obj_h / vs))
        dTdv = np.zeros_like(v)
        g = -2.0 * self.obj_h / vs**2
        dTdv[:-1] += g
        dTdv[1:] += g
        with np.errstate(divide="ignore", invalid="ignore"):
            dvdq = np.where(v > 1e-12, 0.5 / v, 0.0)
        grad = (dTdv * dvdq) @ self.obj_op
        return T / self.t_ref, grad / self.t_ref

    def ineq(self, z: np.ndarray) -> np.ndarray:
        """Every row as g >= 0 (velocity, acceleration both signs, jerk squared per axis)."""
        a = self.acc_op @ z
        q = self.jerk_q @ z
        parts = [self.vel_rhs - self.vel_op @ z, 1.0 - a, 1.0 + a]
        parts += [1.0 - q * (lop @ z) ** 2 for lop in self.jerk_l]
        return np.concatenate(parts)

    def ineq_jac(self, z: np.ndarray) -> np.ndarray:
        q = self.jerk_q @ z
        parts = [-self.vel_op, -self.acc_op, self.acc_op]
        for lop in self.jerk_l:
            L = lop @ z
            parts.append(-((L**2)[:, None] * self.jerk_q + (2.0 * q * L)[:, None] * lop))
        return np.vstack(parts)

    def worst(self, z: np.ndarray) -> float:
        return float(-np.min(self.ineq(z), initial=0.0))


# --- the planner ------------------------------------------------------------------------
@dataclass
class WindowOutcome:
    """What became of one window."""

    s0: float
    s1: float
    n_ctrl: int
    status: str
    start_time: float
    time: float
    iterations: int = 0
    repairs: int = 0
    compute_s: float = 0.0
    profile: FeedProfile | None = field(default=None, repr=False)

    def summary(self) -> dict:
        return {k: getattr(self, k) for k in ("s0", "s1", "n_ctrl", "status", "start_time",
                                              "time", "iterations", "repairs", "compute_s")}


class NLPPlanner:
    """Planner "nlp" (offline reference). start_planner: the feasible plan it starts from
    (default `LPPlanner()`). knot_time: knot spacing where the feed changes, in seconds of
    start-plan motion; min_knot / max_knot: knot spacing bounds (path units); seam_run:
    shortest at-cap stretch that gets a seam; points_per_knot: constraint points per knot
    interval; node_step: fine-grid step of the reconstruction (path units, None: 2 ms of
    the fastest feed); max_repairs: sample-check/tighten rounds per window."""

    name = "nlp"

    def __init__(self, start_planner: Planner | None = None, knot_time: float = 0.04,
                 min_knot: float = 8.0, max_knot: float = 300.0, seam_run: float = 150.0,
                 points_per_knot: int = 8, node_step: float | None = None,
                 margins: Margins = Margins(), max_repairs: int = 3, maxiter: int = 300,
                 ) -> None:
        self.start_planner = start_planner
        self.knot_time = knot_time
        self.min_knot = min_knot
        self.max_knot = max_knot
        self.seam_run = seam_run
        self.points_per_knot = points_per_knot
        self.node_step = node_step
        self.margins = margins
        self.max_repairs = max_repairs
        self.maxiter = maxiter

    def plan(self, request: PlanRequest) -> PlanResult:
        t0 = time.perf_counter()
        start = self._start_result(request)
        path, lim, dt = request.path, request.limits, request.dt
        plan = SampledPlan.of(start, path, lim, dt)
        A, J = path_limits(path, lim)
        vtop = float(np.max(np.minimum(plan.vcap, 1e6)))
        sigma = 0.5 * braking_distance(vtop, A, J)
        rests = np.asarray(path.corners_s(), dtype=float)
        rests = rests[(rests > plan.s[0]) & (rests < plan.s[-1])]
        windows = split_windows(plan, sigma, self.seam_run, rests)
        outcomes = [self._window(request, plan, w, sigma) for w in windows]
        profile = concatenate([o.profile for o in outcomes])
        report = check_positions(sample_plan(path, profile, dt).pos, lim, dt)
        info = {
            "start_method": start.method,
            "start_time_s": start.profile.duration,
            "start_compute_s": start.compute_s,
            "windows": [o.summary() for o in outcomes],
            "n_ctrl_total": int(sum(o.n_ctrl for o in outcomes)),
            "fallback": None,
        }
        if not report.ok:
            info["fallback"] = f"whole job: stitched profile failed the checker ({report.first})"
            profile = start.profile
        info["windows_fallback"] = sum(o.status != "optimized" for o in outcomes)
        return PlanResult(profile, self.name, time.perf_counter() - t0, info)

    # --- internals --------------------------------------------------------------------
    def _start_result(self, request: PlanRequest) -> PlanResult:
        if self.start_planner is None:
            from lookahead.planning.lp import LPPlanner

            self.start_planner = LPPlanner()
        result = self.start_planner.plan(request)
        rep = check_positions(sample_plan(request.path, result.profile, request.dt).pos,
                              request.limits, request.dt)
        if not rep.ok:
            raise PlanningError(f"nlp: the start plan ({result.method}) fails the checker")
        return result

    def _window(self, request: PlanRequest, plan: SampledPlan, win: Window,
                sigma: float) -> WindowOutcome:
        t0 = time.perf_counter()
        k = slice(win.k0, win.k1 + 1)
        s, v = plan.s[k], plan.v[k]
        s0, s1 = float(s[0]), float(s[-1])
        start_piece = slice_profile(plan.result.profile, plan.t[win.k0], plan.t[win.k1])
        sig = min(sigma, 0.5 * (s1 - s0))
        knots = knot_vector(s, v, plan.v[k] >= 0.985 * plan.vcap[k], self.knot_time,
                            self.min_knot, self.max_knot)
        spline = FeedSpline(knots, win, sig, s0, s1)
        out = WindowOutcome(s0, s1, spline.n_ctrl, "start", start_piece.duration,
                            start_piece.duration, profile=start_piece)
        seam0 = None if win.rest0 else self._seam(plan, win.k0)
        seam1 = None if win.rest1 else self._seam(plan, win.k1)
        inner = np.unique(knots)
        pts = np.unique(np.concatenate([
            np.linspace(a, b, self.points_per_knot + 1) for a, b in itertools.pairwise(inner)]
            + [graded_points(s0, s1, s1 - s0, win.rest0, win.rest1, sig)]))
        nodes = graded_points(s0, s1, self._node_step(request), win.rest0, win.rest1, sig)
        margins = PointMargins.uniform(pts, self.margins)

        def vcap_fn(x):
            cap = velocity_cap(request.path, request.limits, x)
            if request.feed_cap is not None:
                cap = np.minimum(cap, request.feed_cap.at(x))
            return cap

        z = None
        try:
            for repair in range(self.max_repairs + 1):
                prob = WindowProblem.build(spline, request.path, request.limits, margins,
                                           vcap_fn, seam0, seam1, nodes)
                if z is None:
                    z = self._start_guess(prob, plan)
                prob.t_ref = max(prob.time(z)[0], 1e-9)
                res = minimize(prob.time, z, jac=True, method="SLSQP",
                               bounds=[(1e-9, 1e6)] * spline.n_ctrl,
                               constraints=self._constraints(prob),
                               options={"maxiter": self.maxiter, "ftol": 1e-10})
                out.iterations += int(res.nit)
                z = res.x
                if prob.worst(z) > 1e-6:
                    out.status = f"fallback: SLSQP ended infeasible ({res.message})"
                    break
                profile = self._profile(spline, z * prob.qs, nodes)
                peaks = window_peaks(request.path, profile, request.limits, request.dt,
                                     hold=win.rest1)
                if peaks.worst <= 1.0:
                    if profile.duration < start_piece.duration:
                        out.status, out.profile, out.time = "optimized", profile, profile.duration
                    else:
                        out.status = "fallback: no faster than the start plan"
                    break
                out.repairs = repair + 1
                radius = max(2.0 * self.min_knot, 0.03 * float(np.max(v)))
                margins.tighten(peaks, lambda tt, p=profile: p.at(tt)[0], radius)
            else:
                out.status = "fallback: still over a limit after repairs"
        except (PlanningError, ValueError, np.linalg.LinAlgError) as exc:
            out.status = f"fallback: {exc}"
        out.compute_s = time.perf_counter() - t0
        return out

    @staticmethod
    def _seam(plan: SampledPlan, k: int) -> tuple[float, float]:
        """(q, dq/ds) of the start plan at sample k (dq/ds = 2 a)."""
        return float(plan.v[k] ** 2), float(2.0 * plan.a[k])

    def _node_step(self, request: PlanRequest) -> float:
        if self.node_step is not None:
            return self.node_step
        return float(0.002 * np.linalg.norm(request.limits.vmax * request.path.path_scale))

    @staticmethod
    def _constraints(prob: WindowProblem) -> list[dict]:
        cons = [{"type": "ineq", "fun": prob.ineq, "jac": prob.ineq_jac}]
        if prob.eq_rhs.size:
            cons.append({"type": "eq", "fun": lambda z: prob.eq_op @ z - prob.eq_rhs,
                         "jac": lambda z: prob.eq_op})
        return cons

    @staticmethod
    def _start_guess(prob: WindowProblem, plan: SampledPlan) -> np.ndarray:
        """The start plan's q fitted (seam states imposed), the free control points scaled
        down until every row holds (bisection on the factor)."""
        sp = prob.spline
        x = np.linspace(sp.s0, sp.s1, 6 * sp.n_ctrl + 20)
        (Q0,) = sp.operators(x, 0)
        target = plan.q_at(x) / prob.qs
        n = sp.n_ctrl
        E, e = prob.eq_op, prob.eq_rhs
        kkt = np.block([[Q0.T @ Q0 + 1e-10 * np.eye(n), E.T],
                        [E, np.zeros((E.shape[0], E.shape[0]))]])
        z_fit = np.linalg.lstsq(kkt, np.concatenate([Q0.T @ target, e]), rcond=None)[0][:n]
        z_fit = np.maximum(z_fit, 1e-6)
        free = np.ones(n, dtype=bool)
        if not sp.window.rest0:
            free[:2] = False
        if not sp.window.rest1:
            free[-2:] = False

        def scaled(f: float) -> np.ndarray:
            return np.where(free, f * z_fit, z_fit)

        if prob.worst(z_fit) <= 0.0:
            return z_fit
        lo, hi = 0.0, 1.0
        if prob.worst(scaled(0.05)) > 0.0:
            return z_fit  # no feasible scaling: let SLSQP find feasibility
        lo = 0.05
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if prob.worst(scaled(mid)) <= 0.0 else (lo, mid)
        return scaled(lo)

    @staticmethod
    def _profile(spline: FeedSpline, c: np.ndarray, nodes: np.ndarray) -> FeedProfile:
        Q0, Q1 = spline.operators(nodes, 1)
        q = np.maximum(Q0 @ c, 0.0)
        v = np.sqrt(q)
        a = 0.5 * (Q1 @ c)
        if spline.window.rest0:
            v[0], a[0] = 0.0, 0.0
        if spline.window.rest1:
            v[-1], a[-1] = 0.0, 0.0
        return hermite_profile(nodes, v, a)


def window_peaks(path: Path, profile: FeedProfile, limits: AxisLimits, dt: float,
                 hold: bool, phases: int = 4) -> SampledRatios:
    """The checker's differences (PROTOCOL.md "Limits") of one window at `phases` sampling
    phases (a window starts at an arbitrary phase of the job's dt grid). Only samples inside
    the window count, except that a window ending at rest holds its end state for 3 samples;
    the seams themselves are judged when the whole job is checked."""
    step = dt / phases
    n = int(np.floor(profile.duration / step + 1e-9)) + 1 + (3 * phases if hold else 0)
    t = np.arange(n) * step
    pos = path.eval_s(profile.at(t)[0], order=0)[0]
    out = []
    for order, lim in ((1, limits.vmax), (2, limits.amax), (3, limits.jmax)):
        d = pos
        for _ in range(order):
            d = d[phases:] - d[:-phases]
        out.append((np.max(np.abs(d) / dt**order / lim, axis=1) if len(d) else np.zeros(0),
                    np.arange(len(d)) * step + 0.5 * order * dt))
    return SampledRatios(out[0][0], out[1][0], out[2][0], out[0][1], out[1][1], out[2][1])


# --- profiles ---------------------------------------------------------------------------
def hermite_profile(s: np.ndarray, v: np.ndarray, a: np.ndarray) -> FeedProfile:
    """C2 s(t) through the nodal states (s_i, v_i, a_i): one quintic per interval, the
    duration from `lp.profile.interval_durations`."""
    h = np.diff(s)
    T = interval_durations(h, v, a)
    c3, c4, c5 = quintic_coefficients(T, h, v[:-1], a[:-1], v[1:], a[1:])
    coeffs = np.stack([c5, c4, c3, 0.5 * a[:-1], v[:-1], s[:-1]])
    return FeedProfile(PPoly(coeffs, np.concatenate([[0.0], np.cumsum(T)]), extrapolate=False))


