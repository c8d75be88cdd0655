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
   budget points; failing segments get their V, A, J lowered and steps 2-5 repeat.
"""

from __future__ import annotations

import time

import numpy as np

from lookahead.planning.base import (
    FeedProfile,
    PathState,
    PlanningError,
    PlanRequest,
    PlanResult,
)
from lookahead.planning.path_limits import (
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
    """

    name = "heuristic"

    def __init__(self, margin: float = 0.98, band_ratio: float = 1.25,
                 max_cell: float | None = None,
                 shares: BudgetShares | None = None, repair_rounds: int = 12) -> None:
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
        starts = choose_segments(grid, vlim, self.band_ratio)
        factor = np.ones(starts.size - 1)
        info: dict = {"rounds": 0, "verified": False}
        profile = None
        for round_ in range(self.repair_rounds):
            budgets = segment_budgets(grid, starts, vlim, limits, self.shares, factor)
            phases, starts, factor, budgets = self._profile_phases(request, grid, starts,
                                                                   factor, budgets, vlim)
            profile = build_profile(phases)
            failing = self._failing_segments(profile, grid, starts, request)
            info["rounds"] = round_ + 1
            if not failing.any():
                info["verified"] = True
                break
            factor = np.where(failing, factor * 0.85, factor)
        info["segments"] = int(starts.size - 1)
        info["cells"] = grid.ncells
        return self._result(profile, t_start, info)

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
        s = grid.s.ravel()
        v, a, j = (x.reshape(grid.s.shape)[:, :, None] for x in state_at_s(profile, s))
        vel = np.abs(grid.xs * v)
        acc = np.abs(grid.xss * v * v + grid.xs * a)
        jerk = np.abs(grid.xsss * v**3 + 3.0 * grid.xss * v * a + grid.xs * j)
        lim = request.limits
        jmax = lim.jmax * grid.jerk_scale[:, None, None]
        bad_cell = np.any((vel > lim.vmax) | (acc > lim.amax) | (jerk > jmax), axis=(1, 2))
        return np.logical_or.reduceat(bad_cell, starts[:-1])


def _forward_pass(w: np.ndarray, b: SegmentBudgets) -> None:
    """Lower junction feeds 2.. in place to what each segment can reach from the last."""
    for k in range(1, b.L.size):
        w[k + 1] = min(w[k + 1], reachable_feed(w[k], b.L[k] * _SLACK, b.A[k], b.J[k]))


def _rest_profile(s: float, dt: float) -> FeedProfile:
    """A profile that stays at s for one sample time."""
    from scipy.interpolate import PPoly

    return FeedProfile(PPoly(np.array([[0.0], [0.0], [0.0], [s]]), np.array([0.0, dt])))


def plan_rest_to_rest(path, limits, dt: float = 0.001, **kwargs) -> PlanResult:
    """Convenience: the whole path from rest to rest with the heuristic planner."""
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=dt)
    return HeuristicPlanner(**kwargs).plan(request)


__all__ = ["HeuristicPlanner", "plan_rest_to_rest"]
