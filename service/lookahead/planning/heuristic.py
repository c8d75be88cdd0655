"""The heuristic planner (paper 3.2): S-curves per planning segment, junction feeds from
kinematic compatibility, axis limits verified along the path and repaired.

1. Geometry on a grid of cells -> feed limit per cell (axis velocity, centripetal
   acceleration, geometric jerk, C1-knot cap, feed cap); cells grouped into planning
   segments by bands of that limit (`path_limits`).
2. Per segment a cruise cap V and path acceleration / jerk budgets A, J that keep every
   axis term within its limit.
3. Junction feeds: each junction at most the caps of both neighbours (0 at corners and at a
   rest end), then a backward and a forward pass so that every segment can make its feed
   change within its length (`scurve.reachable_feed`). The first segment starts in the
   request's arbitrary state (v, a); its end feed is found by bisection on Ruckig's
   feasibility, and if it cannot even stop there it is merged with the next segment.
4. One Ruckig S-curve per segment (1 DOF along s) -> phases -> s(t) as a PPoly.
5. Verification of axis velocity, acceleration and jerk at the check points between the
   budget points; failing segments get their V, A, J lowered and steps 2-5 repeat. A
   profile that still fails raises PlanningError (never an unverified profile).
6. A start above the limits (the service replans after an override down or a lower feed
   cap): first a brake (Ruckig's velocity interface) down to the feed limit within the
   limits time-scaled by the smallest factor that admits the start state, then steps 1-5.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.planning.base import (
    FeedProfile,
    PathState,
    PlanningError,
    PlanRequest,
    PlanResult,
)
from lookahead.planning.path_limits import (
    BUDGET_FRACTIONS,
    BudgetShares,
    PathGrid,
    SegmentBudgets,
    build_grid,
    choose_segments,
    feed_limit,
    segment_budgets,
)
from lookahead.planning.profile_build import build_profile, concat_phases, state_at_s
from lookahead.planning.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    reachable_feed,
)

_SLACK = 1.0 - 1e-9  # plan feed changes into a hair less than the segment length


class HeuristicPlanner:
    """Paper 3.2 heuristic: S-curve segments, bisection on compatibility, verify + repair.

    margin: fraction of each axis limit planned to (the checker judges at 1.0).
    band_ratio: feed-limit ratio that starts a new planning segment.
    max_cell: longest geometry cell (path units; default path length / 2000).
    repair_rounds: verification/repair passes before giving up.
    brake_within_limits: when the plan from a moving start fails, try the brake fallback
    (brake, then plan the rest) also if the start state is within the limits. False for a
    shortest-stop search (`stream.plans.shortest_stop`): its too-short trials then fail in
    ~2 ms instead of ~20, and on the tubes the fallback rescued none of them.
    """

    name = "heuristic"

    def __init__(self, margin: float = 0.98, band_ratio: float = 1.25,
                 max_cell: float | None = None,
                 shares: BudgetShares | None = None, repair_rounds: int = 12,
                 brake_within_limits: bool = True) -> None:
        self.brake_within_limits = brake_within_limits
        self.margin = margin
        self.band_ratio = band_ratio
        self.max_cell = max_cell
        self.shares = shares or BudgetShares()
        self.repair_rounds = repair_rounds
        self._solver = SCurveSolver()

    # --- public ---------------------------------------------------------------------
    def plan(self, request: PlanRequest) -> PlanResult:
        t_start = time.perf_counter()
        start = request.start
        s_end = float(request.s_end)
        if not s_end > start.s:
            if s_end == start.s and start.v == 0 and start.a == 0:
                return self._result(_rest_profile(start.s, request.dt), t_start, {"segments": 0})
            raise PlanningError(f"s_end ({s_end}) must lie after start.s ({start.s})")
        if start.v < 0 or request.v_end < 0:
            raise PlanningError("feeds must be >= 0")
        limits = request.limits.scaled(self.margin)
        grid = build_grid(request.path, start.s, s_end, request.dt, limits, self.shares,
                          request.feed_cap, self.max_cell)
        vlim = feed_limit(grid, limits, self.shares, request.feed_cap)
        info: dict = {}
        first_problem = ""
        if not self._start_above_limits(request, grid, vlim):
            try:
                phases, core = self._plan_phases(request, grid, vlim, limits)
                return self._result(build_profile(phases), t_start, {**info, **core})
            except PlanningError as exc:
                if start.v == 0 and start.a == 0:
                    raise
                if not self.brake_within_limits and _state_scale(request, grid) <= 1.0:
                    raise
                first_problem = str(exc)  # perhaps the start acceleration is too high
        # brake to the limits first; if the rest cannot follow from there (the window is
        # too short for that feed), brake to a lower feed
        problem = ""
        for fraction in _BRAKE_TARGETS:
            brake, g = self._brake(request, grid, vlim, limits, fraction)
            end = _end_state(brake)
            if not end.s < s_end:
                break
            rest = replace(request, start=end)
            rest_grid = build_grid(request.path, end.s, s_end, request.dt, limits,
                                   self.shares, request.feed_cap, self.max_cell)
            rest_vlim = feed_limit(rest_grid, limits, self.shares, request.feed_cap)
            try:
                phases, core = self._plan_phases(rest, rest_grid, rest_vlim, limits)
            except PlanningError as exc:
                problem = str(exc)
                continue
            info = {"brake_scale": g, "brake_target": fraction, **core}
            profile = build_profile(concat_phases([brake, phases]))
            return self._result(profile, t_start, info)
        raise PlanningError("the start state cannot slow down to the limits within the "
                            f"window [{start.s}, {s_end}]: {first_problem} {problem}")

    def _plan_phases(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                     limits: AxisLimits) -> tuple[Phases, dict]:
        """Segments, S-curves, verification and repair from a start within the limits."""
        starts = choose_segments(grid, vlim, self.band_ratio)
        factor = np.ones(starts.size - 1)
        info: dict = {"rounds": 0, "verified": False}
        phases = None
        for round_ in range(self.repair_rounds):
            budgets = segment_budgets(grid, starts, vlim, limits, self.shares, factor)
            phases, starts, factor, budgets = self._profile_phases(request, grid, starts,
                                                                   factor, budgets, vlim)
            failing = self._failing_segments(build_profile(phases), grid, starts, request)
            info["rounds"] = round_ + 1
            if not failing.any():
                info["verified"] = True
                break
            factor = np.where(failing, factor * 0.85, factor)
        info["segments"] = int(starts.size - 1)
        info["cells"] = grid.ncells
        if not info["verified"]:
            raise PlanningError(f"heuristic: no profile within the limits after "
                                f"{info['rounds']} repair rounds")
        return phases, info

    # --- a start state above the limits (override down, lower feed cap) ---------------
    def _start_above_limits(self, request: PlanRequest, grid: PathGrid,
                            vlim: np.ndarray) -> bool:
        """True if the start feed is beyond the first cell's feed limit even with the
        stretch `_first_segment` grants (1 / margin). A too high start acceleration shows
        as a failure of the normal plan, which then falls back to a brake."""
        return bool(request.start.v > vlim[0] / self.margin)

    def _brake(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
               limits: AxisLimits, fraction: float) -> tuple[Phases, float]:
        """The fastest feed change from the start state down to `fraction` of the feed
        limit, path acceleration 0, that keeps every axis within the limits time-scaled
        by g (v g, a g^2, j g^3), g >= 1 as small as found (coarse scan, then bisection).
        The start came from a plan under limits the service scaled down (override) or
        under a higher feed cap, so a g that fits the start exists (the old limits).
        Verified at the grid points; raises PlanningError if no brake is found."""

        def fits(g: float) -> bool:
            return self._brake_at(request, grid, vlim, limits, g, 1.0, fraction) is not None

        st = request.start
        lo, hi = None, None
        for g in _BRAKE_SCALES:
            if fits(g):
                hi = g
                break
            lo = g
        if hi is None:
            raise PlanningError(f"the start state (v={st.v:.6g}, a={st.a:.6g}) cannot be "
                                "brought within the limits")
        if lo is not None:
            for _ in range(12):  # the start fits from some g on: bisect for it
                mid = float(np.sqrt(lo * hi))
                lo, hi = (lo, mid) if fits(mid) else (mid, hi)
        # the brake is judged at the scaling the start state itself needs (1 if it is
        # within the request's limits): the budget model's conservatism gets no room
        check = _time_scaled(request.limits, max(1.0, _state_scale(request, grid) * (1 + 1e-6)))
        for shrink in _BRAKE_SHRINK:
            found = self._brake_at(request, grid, vlim, limits, hi, shrink, fraction)
            if found is None:
                break
            phases, ncell = found
            if not self._brake_fails(phases, grid, ncell, check):
                return phases, hi
        raise PlanningError(f"no brake within the limits from v={st.v:.6g}, a={st.a:.6g}")

    def _brake_at(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                  limits: AxisLimits, g: float, shrink: float,
                  fraction: float) -> tuple[Phases, int] | None:
        """Brake phases under `limits` time-scaled by g (budgets times `shrink`) and the
        number of cells they cover, or None if the start state does not fit. The cells
        the brake runs over are found by fixed-point iteration (budgets -> length -> cells).
        As in `_first_segment`, the acceleration budget stretches by 1 / margin to admit
        the start acceleration (the brake is verified at the unmargined limits)."""
        st = request.start
        lim = _time_scaled(limits, g)
        nb = BUDGET_FRACTIONS.size
        feed = np.array([st.v])  # an upper bound of the brake's feed in each cell
        for _ in range(16):
            ncell = feed.size
            sub = _first_cells(grid, ncell)
            # each cell its own "segment" at its own feed bound, then the smallest budgets
            b = segment_budgets(sub, np.arange(ncell + 1), feed, lim, self.shares)
            A, J = float(np.min(b.A)), float(np.min(b.J)) * shrink
            A = max(A * shrink, min(A, abs(st.a)))
            if abs(st.a) > A and abs(st.a) <= A / self.margin:
                A = abs(st.a)
            fast = np.any(np.abs(sub.xs[:, :nb]) * feed[:, None, None] > lim.vmax)
            if fast or abs(st.a) > A or not J > 0:
                return None
            target = min(float(np.min(vlim[:ncell])) * fraction, st.v)
            phases = self._solver.feed_change(st.s, st.v, st.a, target, A, J)
            if not phases.duration.size:
                return None  # already there: nothing a brake could change
            need = int(np.searchsorted(grid.edges, _end_state(phases).s, side="left"))
            need = min(max(need, 1), grid.ncells)
            actual = _cell_feed_bound(phases, grid, max(need, ncell))
            grown = np.concatenate([feed, actual[ncell:]])
            if need <= ncell and np.all(actual[:ncell] <= feed * (1 + 1e-9)):
                return phases, ncell
            feed = np.maximum(grown, actual)
        return None

    def _brake_fails(self, phases: Phases, grid: PathGrid, ncell: int,
                     lim: AxisLimits) -> bool:
        """True if some axis exceeds `lim` at a grid point the brake passes."""
        s_end = _end_state(phases).s
        sub = _first_cells(grid, ncell)
        inside = sub.s <= s_end
        v, a, j = (x.reshape(sub.s.shape)[:, :, None]
                   for x in state_at_s(build_profile(phases), sub.s.ravel()))
        vel = np.abs(sub.xs * v)
        acc = np.abs(sub.xss * v * v + sub.xs * a)
        jerk = np.abs(sub.xsss * v**3 + 3.0 * sub.xss * v * a + sub.xs * j)
        bad = (vel > lim.vmax) | (acc > lim.amax) | (jerk > lim.jmax)
        return bool(np.any(bad & inside[:, :, None]))

    # --- steps ------------------------------------------------------------------------
    def _result(self, profile: FeedProfile, t_start: float, info: dict) -> PlanResult:
        return PlanResult(profile, self.name, time.perf_counter() - t_start, info)

    def _profile_phases(self, request: PlanRequest, grid: PathGrid, starts: np.ndarray,
                        factor: np.ndarray, budgets: SegmentBudgets, vlim: np.ndarray):
        """Junction feeds and one Ruckig S-curve per segment. If the start state cannot
        reach a valid end state within the first segment, its cruise cap is first lowered
        to the start feed (which raises its acceleration and jerk budgets), then leading
        segments are merged."""
        limits = request.limits.scaled(self.margin)
        lowered = False
        while True:
            w_hi = self._junction_feeds(request, grid, starts, budgets)
            try:
                first, w1 = self._first_segment(request, budgets, w_hi[1])
                break
            except SegmentInfeasibleError:
                v_cap = np.full(starts.size - 1, np.inf)
                if not lowered and request.start.v > 0:
                    lowered = True
                    v_cap[0] = request.start.v
                elif starts.size <= 2:
                    raise PlanningError("the start state cannot stop within the window "
                                        f"[{request.start.s}, {request.s_end}]") from None
                else:
                    lowered = False
                    starts = np.delete(starts, 1)
                    factor = np.delete(factor, 1)
                    v_cap = v_cap[1:]
                budgets = segment_budgets(grid, starts, vlim, limits, self.shares, factor,
                                          v_cap)
        w = w_hi.copy()
        if w1 < w[1]:
            w[1] = w1
            _forward_pass(w, budgets)
        parts = [first]
        b = budgets
        for k in range(1, b.L.size):
            parts.append(self._later_segment(k, b, w))
        return concat_phases(parts), starts, factor, budgets

    def _junction_feeds(self, request: PlanRequest, grid: PathGrid, starts: np.ndarray,
                        b: SegmentBudgets) -> np.ndarray:
        """Upper bounds of the junction feeds (nseg + 1,), junction 0 being the start."""
        nseg = b.L.size
        w = np.empty(nseg + 1)
        w[0] = request.start.v
        w[1:-1] = np.minimum(b.V[:-1], b.V[1:])
        w[1:-1][grid.corner_after[starts[1:-1] - 1]] = 0.0
        w[-1] = min(request.v_end, b.V[-1])
        # Scalar loops: each junction depends on its neighbour's result.
        for k in range(nseg - 1, 0, -1):
            w[k] = min(w[k], reachable_feed(w[k + 1], b.L[k] * _SLACK, b.A[k], b.J[k]))
        _forward_pass(w, b)
        return w
    def _first_segment(self, request: PlanRequest, b: SegmentBudgets,
                       w1_hi: float) -> tuple[Phases, float]:
        """S-curve from the start state to the highest feasible end feed <= w1_hi, by
        bisection on Ruckig's feasibility (raises SegmentInfeasibleError if none is)."""
        st = request.start
        args = (float(b.s0[0]), float(b.L[0]), st.v, st.a)
        # A start state from a plan of the same path may sit a hair outside this window's
        # budgets (other cells, other sample points); within the margin to the true limits
        # the budgets stretch to include it instead of braking.
        stretch = 1.0 / self.margin
        V, A = float(b.V[0]), float(b.A[0])
        V = max(V, st.v) if st.v <= V * stretch else V
        A = max(A, abs(st.a)) if abs(st.a) <= A * stretch else A
        caps = (V, A, float(b.J[0]))

        def attempt(w1: float) -> Phases | None:
            try:
                return self._solver.segment(*args, w1, *caps)
            except SegmentInfeasibleError:
                return None

        best = attempt(w1_hi)
        if best is not None:
            return best, w1_hi
        # feasible end feeds form an interval; find one, then bisect upwards towards w1_hi
        lo = None
        for w in np.linspace(0.0, w1_hi, 9)[:-1]:
            best = attempt(float(w))
            if best is not None:
                lo = float(w)
        if lo is None:
            raise SegmentInfeasibleError("no end feed reachable from the start state")
        hi = min(w1_hi, lo + w1_hi / 8.0)
        best = attempt(lo)
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            trial = attempt(mid)
            if trial is None:
                hi = mid
            else:
                lo, best = mid, trial
            if hi - lo <= 1e-6 * max(w1_hi, 1e-12):
                break
        return best, lo

    def _later_segment(self, k: int, b: SegmentBudgets, w: np.ndarray) -> Phases:
        """S-curve (w[k], 0) -> (w[k+1], 0); if rounding defeats Ruckig at the exact
        compatibility limit, lower the end feed slightly (written back into w)."""
        for attempt in range(8):
            try:
                return self._solver.segment(float(b.s0[k]), float(b.L[k]), float(w[k]), 0.0,
                                            float(w[k + 1]), float(b.V[k]), float(b.A[k]),
                                            float(b.J[k]))
            except SegmentInfeasibleError:
                w[k + 1] *= 1.0 - 10.0 ** (attempt - 7)
        raise PlanningError(f"segment {k} at s={b.s0[k]:.6g}: no S-curve from feed {w[k]:.6g}")

    def _failing_segments(self, profile: FeedProfile, grid: PathGrid, starts: np.ndarray,
                          request: PlanRequest) -> np.ndarray:
        """Segments where some axis exceeds its full limit at a grid point."""
        ncell, npts, naxes = grid.xs.shape
        v, a, j = (x[:, None] for x in state_at_s(profile, grid.s.ravel()))
        # flat (points, axes) views: one pass per term, no broadcasting over cell axes
        xs, xss, xsss = (x.reshape(-1, naxes) for x in (grid.xs, grid.xss, grid.xsss))
        lim = request.limits
        jmax = (lim.jmax if np.all(grid.jerk_scale == 1.0)
                else np.repeat(grid.jerk_scale, npts)[:, None] * lim.jmax)
        bad = np.abs(xs * v) > lim.vmax
        bad |= np.abs(xss * (v * v) + xs * a) > lim.amax
        bad |= np.abs(xsss * (v * v * v) + xss * (3.0 * v * a) + xs * j) > jmax
        bad_cell = bad.reshape(ncell, -1).any(axis=1)
        return np.logical_or.reduceat(bad_cell, starts[:-1])


def _forward_pass(w: np.ndarray, b: SegmentBudgets) -> None:
    """Lower junction feeds 2.. in place to what each segment can reach from the last."""
    for k in range(1, b.L.size):
        w[k + 1] = min(w[k + 1], reachable_feed(w[k], b.L[k] * _SLACK, b.A[k], b.J[k]))


#: time scalings g of the limits tried for a brake, smallest first
_BRAKE_SCALES = (1.0, *np.geomspace(1.05, 20.0, 40))
#: fractions of the feed limit a brake aims at, tried in turn
_BRAKE_TARGETS = (1.0, 0.7, 0.5, 0.3, 0.15, 0.05)
#: budget shrink factors tried for a brake that fails verification
_BRAKE_SHRINK = (1.0, 0.85, 0.7, 0.5)


def _time_scaled(limits: AxisLimits, g: float) -> AxisLimits:
    """Limits (v g, a g^2, j g^3): what the same motion needs when run g times faster."""
    return AxisLimits(limits.vmax * g, limits.amax * g * g, limits.jmax * g**3)


def _state_scale(request: PlanRequest, grid: PathGrid) -> float:
    """The smallest time scaling g of the request's limits (v g, a g^2) that the start
    state's axis velocity and acceleration fit in (at the grid's first point)."""
    st = request.start
    xs, xss = grid.xs[0, 0], grid.xss[0, 0]
    lim = request.limits
    g_v = np.max(np.abs(xs * st.v) / lim.vmax)
    g_a = np.sqrt(np.max(np.abs(xss * st.v**2 + xs * st.a) / lim.amax))
    return float(max(g_v, g_a))


def _cell_feed_bound(phases: Phases, grid: PathGrid, ncell: int) -> np.ndarray:
    """An upper bound of the feed of `phases` in each of the first `ncell` cells: the
    larger of the feeds at the cell's ends, and the peak feed in the cells it lies in
    (a brake's feed first rises while the start acceleration runs out, then falls)."""
    profile = build_profile(phases)
    at_edges = state_at_s(profile, grid.edges[:ncell + 1])[0]
    bound = np.maximum(at_edges[:-1], at_edges[1:])
    t = np.concatenate([[0.0], np.cumsum(phases.duration)])
    s_v = profile.at(t)[:2]
    where = np.clip(np.searchsorted(grid.edges, s_v[0], side="right") - 1, 0, ncell - 1)
    np.maximum.at(bound, where, s_v[1])
    return bound


def _first_cells(grid: PathGrid, ncell: int) -> PathGrid:
    """The grid cut to its first `ncell` cells."""
    return replace(grid, edges=grid.edges[:ncell + 1], s=grid.s[:ncell], xs=grid.xs[:ncell],
                   xss=grid.xss[:ncell], xsss=grid.xsss[:ncell],
                   jerk_scale=grid.jerk_scale[:ncell], c1_cap=grid.c1_cap[:ncell],
                   corner_after=grid.corner_after[:ncell])


def _end_state(phases: Phases) -> PathState:
    """Position, feed and acceleration at the end of the last phase."""
    h, j, a, v, s = (float(x[-1]) for x in (phases.duration, phases.jerk, phases.acc,
                                            phases.vel, phases.pos))
    end_s = s + v * h + a * h * h / 2.0 + j * h**3 / 6.0
    return PathState(end_s, max(v + a * h + j * h * h / 2.0, 0.0), a + j * h)


def _rest_profile(s: float, dt: float) -> FeedProfile:
    """A profile that stays at s for one sample time."""
    from scipy.interpolate import PPoly

    return FeedProfile(PPoly(np.array([[0.0], [0.0], [0.0], [s]]), np.array([0.0, dt])))


def plan_rest_to_rest(path, limits, dt: float = 0.001, **kwargs) -> PlanResult:
    """Convenience: the whole path from rest to rest with the heuristic planner."""
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=dt)
    return HeuristicPlanner(**kwargs).plan(request)


__all__ = ["HeuristicPlanner", "plan_rest_to_rest"]
