"""The LP feed planner (the paper's 3.3, Fan et al.): q = (ds/dt)^2 on an s-grid.

Pass 0 solves the velocity + acceleration LP; later passes add the jerk rows linearized
at the last solution (tangent of J / sqrt(q), conservative at the nodes) and stop when
the travel time no longer improves. The grid solution becomes a C2 quintic profile
(`grid_profile`), whose continuous axis velocity, acceleration and jerk are checked every
dt/2 (`sampled_check.analytic_ratios`, a bound on the checker's finite differences);
where it breaks a limit (between nodes the jerk can overshoot), the rows of the nearby
nodes are tightened and one jerk pass is solved again (the repair loop).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile, PlanningError, PlanRequest, PlanResult
from lookahead.planning.grid_profile import grid_time, profile_from_grid
from lookahead.planning.lp_envelope import braking_distance, path_limits, reachable_q
from lookahead.planning.lp_grid import build_grid
from lookahead.planning.lp_rows import (
    GridGeometry,
    Rows,
    acceleration_rows,
    end_acceleration_rows,
    jerk_change_rows,
    jerk_rows,
    start_slope_row,
    velocity_caps,
)
from lookahead.planning.lp_solve import ScaledLP, make_backend
from lookahead.planning.sampled_check import SampledRatios, analytic_ratios

_REST = 1e-9  # feeds below this (path units / s) count as rest


@dataclass
class Tightening:
    """Per-node factors (<= 1) on the velocity, acceleration and jerk limits."""

    vel: np.ndarray
    acc: np.ndarray
    jerk: np.ndarray

    @classmethod
    def uniform(cls, n: int, vel: float, acc: float, jerk: float) -> Tightening:
        return cls(np.full(n, vel), np.full(n, acc), np.full(n, jerk))


@dataclass
class GridPlan:
    """An LP solution on the grid and the history of its passes."""

    s: np.ndarray
    q: np.ndarray
    time_s: float
    pass_times: list[float] = field(default_factory=list)
    solver_ms: list[float] = field(default_factory=list)
    statuses: list[str] = field(default_factory=list)


def default_grid_step(path: Path, limits: AxisLimits, interval_s: float = 0.0045) -> float:
    """Grid spacing: the distance covered in `interval_s` at the fastest feed the axis
    velocity limits could allow (path units)."""
    return float(interval_s * np.linalg.norm(limits.vmax * path.path_scale))


def c1_knot_caps(path: Path, s: np.ndarray, limits: AxisLimits, dt: float) -> np.ndarray:
    """Feed cap at the nodes next to C1 knots: sqrt(jmax dt / |jump of x_ss|) (DESIGN.md)."""
    caps = np.full(s.size, np.inf)
    if path.continuity() >= 2:
        return caps
    knots = path.breakpoints_s()
    knots = knots[(knots > s[0]) & (knots < s[-1])]
    if knots.size == 0:
        return caps
    eps = 1e-7 * max(path.length, 1.0)
    jump = np.abs(path.eval_s(knots + eps, 2)[2] - path.eval_s(knots - eps, 2)[2])
    with np.errstate(divide="ignore"):
        vcap = np.min(np.sqrt(limits.jmax * dt / jump), axis=1)
    idx = np.searchsorted(s, knots)
    for lo, v in zip(idx, vcap, strict=True):
        sl = slice(max(lo - 2, 0), min(lo + 2, s.size))
        caps[sl] = np.minimum(caps[sl], v)
    return caps


class LPPlanner:
    """Planner "lp". solver: "highs" (default: scipy's HiGHS, the faster one measured) or
    "osqp".

    grid_step: node spacing in path units (None: `default_grid_step`). max_passes: jerk
    re-linearizations. max_repairs: check/tighten rounds (each re-solves one jerk pass).
    margins: initial factors on (vmax, amax, jmax) in the LP rows (the jerk margin absorbs
    most of the overshoot between nodes, so repairs are rare). jerk_step: the largest
    change of the nodal axis jerk between neighbouring nodes, as a fraction of jmax (a
    regularizer). check_step: spacing of the analytic verification, in units of the
    request's dt. envelope_jerk: factor on the path jerk of the start/stop S-curve
    envelopes (the reconstruction overshoots most on the graded grid near rest).
    """

    name = "lp"

    def __init__(
        self,
        solver: str = "highs",
        grid_step: float | None = None,
        max_passes: int = 1,
        max_repairs: int = 8,
        margins: tuple[float, float, float] = (0.995, 0.98, 0.85),
        verify: bool = True,
        jerk_step: float = 0.3,
        check_step: float = 0.5,
        envelope_jerk: float = 0.7,
        envelope_margin: float = 0.85,
        zone_pad: int = 10,
        free_start_nodes: int = 3,
    ) -> None:
        self.free_start_nodes = free_start_nodes
        self.envelope_margin = envelope_margin
        self.zone_pad = zone_pad
        self.envelope_jerk = envelope_jerk
        self.check_step = check_step
        self.jerk_step = jerk_step
        self.solver = solver
        self.backend = make_backend(solver)
        self.grid_step = grid_step
        self.max_passes = max_passes
        self.max_repairs = max_repairs
        self.margins = margins
        self.verify = verify

    # --- public -----------------------------------------------------------------------
    def plan(self, request: PlanRequest, fixed_head: np.ndarray | None = None) -> PlanResult:
        """Plan [start.s, s_end]. fixed_head: q values to impose on the first nodes
        (the windowed driver passes the committed nodes of the previous window)."""
        t0 = time.perf_counter()
        s, stop_idx = self.grid(request)
        geo = GridGeometry.sample(request.path, s)
        tight = Tightening.uniform(s.size, *self.margins)
        self._pretighten(request, geo, tight, stop_idx)
        plan = self.solve_grid(request, geo, tight, stop_idx, fixed_head)
        repairs = 0
        worst = float("nan")
        while True:
            profile = self._profile(request, plan)
            if not self.verify:
                break
            ratios = analytic_ratios(request.path, profile, request.limits, geo,
                                     self.check_step * request.dt)
            worst = ratios.worst
            if worst <= 1.0:
                break
            if repairs >= self.max_repairs:
                raise PlanningError(
                    f"lp: sampled profile still exceeds the limits by {100 * (worst - 1):.1f} %"
                    f" after {repairs} repairs"
                )
            self._tighten(tight, ratios, profile, s, request.dt)
            plan = self.solve_grid(request, geo, tight, stop_idx, fixed_head, start_q=plan.q,
                                   passes=1)
            repairs += 1
        info = {
            "solver": self.solver,
            "nodes": int(s.size),
            "pass_times_s": plan.pass_times,
            "solver_ms": plan.solver_ms,
            "statuses": plan.statuses,
            "repairs": repairs,
            "worst_ratio": worst,
            "grid_s": s,
            "grid_q": plan.q,
        }
        return PlanResult(profile, self.name, time.perf_counter() - t0, info)

    def grid(self, request: PlanRequest) -> tuple[np.ndarray, np.ndarray]:
        """The nodes of the request's stretch and the indices of interior rest nodes."""
        s0, s1 = float(request.start.s), float(request.s_end)
        if not s1 > s0:
            raise PlanningError(f"lp: s_end {s1} must exceed start.s {s0}")
        h = self.grid_step or default_grid_step(request.path, request.limits)
        corners = np.asarray(request.path.corners_s(), dtype=float)
        return build_grid(s0, s1, h, request.start.v <= _REST, request.v_end <= _REST, corners)

    def solve_grid(
        self,
        request: PlanRequest,
        geo: GridGeometry,
        tight: Tightening,
        stop_idx: np.ndarray,
        fixed_head: np.ndarray | None = None,
        start_q: np.ndarray | None = None,
        passes: int | None = None,
    ) -> GridPlan:
        """Velocity+acceleration pass (unless start_q is given), then up to `passes`
        (default max_passes) jerk passes."""
        lim = request.limits
        q_hi = np.minimum(self._caps(request, geo, tight),
                          self._envelope(request, geo, tight, stop_idx))
        q_lo = np.zeros_like(q_hi)
        fixed = {0: request.start.v**2, geo.n_nodes - 1: request.v_end**2}
        fixed.update({int(i): 0.0 for i in stop_idx})
        if fixed_head is not None:
            fixed.update({i: float(v) for i, v in enumerate(fixed_head)})
        for i, val in fixed.items():
            q_lo[i] = val
            q_hi[i] = max(val, 0.0)
        base = [acceleration_rows(geo, lim.amax, tight.acc)]
        if request.v_end > _REST:
            base.append(end_acceleration_rows(geo, lim.amax, float(tight.acc[-1])))
        if request.start.v > _REST and fixed_head is None:
            base.append(start_slope_row(geo, request.start.a))
        weight = np.gradient(geo.s)
        plan = GridPlan(geo.s, np.zeros(geo.n_nodes), np.inf)
        q_star = start_q
        if q_star is None:
            q_star = self._solve(plan, weight, q_lo, q_hi, base, geo.n_nodes, record=False)
        q_floor = 1e-6 * float(np.max(q_hi))
        rest = [i for i, val in fixed.items() if val <= _REST**2]
        if request.start.v > _REST:
            # the moving start's own jerk is whatever its previous plan had: the
            # jerk-change regularizer there made replans from braking states infeasible
            rest += list(range(self.free_start_nodes))
        rest = np.unique(np.array(rest, dtype=int))
        best_q, best_t = None, np.inf
        for _ in range(passes or self.max_passes):
            rows = [*base, jerk_rows(geo, lim.jmax, tight.jerk, q_star, q_floor),
                    jerk_change_rows(geo, lim.jmax, q_star, q_floor, self.jerk_step, rest)]
            q = self._solve(plan, weight, q_lo, q_hi, rows, geo.n_nodes, record=True)
            t = grid_time(geo.s, q)
            plan.pass_times.append(t)
            if t >= best_t * (1.0 - 1e-4):
                break
            best_q, best_t, q_star = q, t, q
        if best_q is None:
            raise PlanningError("lp: the jerk LP has no solution")
        plan.q, plan.time_s = best_q, best_t
        return plan

    # --- internals --------------------------------------------------------------------
    def _solve(self, plan: GridPlan, weight, q_lo, q_hi, rows: list[Rows], n: int,
               record: bool) -> np.ndarray:
        lp = ScaledLP.build(weight, q_lo, q_hi, Rows.stack(rows, n))
        t0 = time.perf_counter()
        out = self.backend.solve(lp)
        plan.solver_ms.append(1e3 * (time.perf_counter() - t0))
        plan.statuses.append(out.status)
        if not out.ok:
            raise PlanningError(f"lp: {self.solver} returned {out.status}")
        return out.q

    def _caps(self, request: PlanRequest, geo: GridGeometry, tight: Tightening) -> np.ndarray:
        lim = request.limits
        vcap = np.sqrt(velocity_caps(geo, lim.vmax)) * tight.vel
        vcap = np.minimum(vcap, c1_knot_caps(request.path, geo.s, lim, request.dt))
        if request.feed_cap is not None:
            vcap = np.minimum(vcap, request.feed_cap.at(geo.s))
        return vcap**2

    def _envelope(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                  stop_idx: np.ndarray, include_start: bool = True) -> np.ndarray:
        """Jerk-limited S-curve bounds on q after the start (unless not `include_start`),
        before a rest end and around interior stops (`lp_envelope`)."""
        A, J = path_limits(request.path, request.limits)
        s = geo.s
        # one S-curve per prescribed state, with the tightest factors of its reach
        reach = braking_distance(float(np.sqrt(np.max(velocity_caps(geo, request.limits.vmax)))),
                                 A, J)

        def factors(centre: float) -> tuple[float, float]:
            near = np.abs(s - centre) <= reach
            return (self.envelope_jerk * J * float(np.min(tight.jerk[near])),
                    A * float(np.min(tight.acc[near])))

        a0 = request.start.a
        env = np.full(s.size, np.inf)
        if include_start:
            Jn, An = factors(s[0])
            env = reachable_q(s - s[0], request.start.v, a0, Jn, max(An, a0 + 1e-6 * abs(a0)))
        if request.v_end <= _REST:
            env = np.minimum(env, reachable_q(s[-1] - s, 0.0, 0.0, *factors(s[-1])))
        for i in stop_idx:
            env = np.minimum(env, reachable_q(np.abs(s - s[i]), 0.0, 0.0, *factors(s[i])))
        return env

    def _pretighten(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                    stop_idx: np.ndarray) -> None:
        """Scale the jerk factor by `envelope_margin` where a start/stop envelope bounds
        q (and a few nodes around it): where the envelope's straight q (constant path
        acceleration) meets the velocity cap, the quintic reconstruction overshoots the
        nodal jerk by ~15 % (measured), which otherwise costs a repair round per window.
        Not after a moving start: there the committed state may need the full jerk (a
        tighter row at the first nodes made replans infeasible)."""
        if self.envelope_margin >= 1.0:
            return
        env = self._envelope(request, geo, tight, stop_idx,
                             include_start=request.start.v <= _REST)
        zone = env < self._caps(request, geo, tight)
        if not np.any(zone):
            return
        grown = zone.copy()
        for off in range(1, self.zone_pad + 1):
            grown[off:] |= zone[:-off]
            grown[:-off] |= zone[off:]
        tight.jerk[grown] *= self.envelope_margin

    def _profile(self, request: PlanRequest, plan: GridPlan) -> FeedProfile:
        a_end = 0.0 if request.v_end <= _REST else None
        return profile_from_grid(plan.s, plan.q, request.start.a, a_end)

    @staticmethod
    def _tighten(tight: Tightening, ratios: SampledRatios, profile: FeedProfile,
                 s: np.ndarray, dt: float) -> None:
        """Scale the limits down around every time where one was exceeded."""
        t_nodes = profile.s_of_t.x - profile.s_of_t.x[0]
        for arr, t_at, factors in ((ratios.vel, ratios.t_vel, tight.vel),
                                   (ratios.acc, ratios.t_acc, tight.acc),
                                   (ratios.jerk, ratios.t_jerk, tight.jerk)):
            bad = np.nonzero(arr > 1.0)[0]
            if bad.size == 0:
                continue
            node = np.clip(np.searchsorted(t_nodes, t_at[bad]) - 1, 0, s.size - 1)
            shrink = np.clip(0.98 / arr[bad], 0.6, 0.97)
            per_node = np.ones(s.size)
            for i, f in zip(node, shrink, strict=True):
                sl = slice(max(i - 2, 0), min(i + 4, s.size))
                per_node[sl] = np.minimum(per_node[sl], f)
            factors *= per_node
