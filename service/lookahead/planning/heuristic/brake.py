"""A start state above the limits (the service replans after an override down or a lower
feed cap): the fastest feed change down to a fraction of the feed limit, path acceleration
0, within the limits time-scaled by the smallest factor g >= 1 that admits the start state
(the start came from a plan under those scaled limits: the old ones).

Units: path units (mm), seconds; limits per axis as in `lookahead.limits`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanningError, PlanRequest
from lookahead.planning.heuristic.path_limits import (
    BUDGET_FRACTIONS,
    BudgetShares,
    PathGrid,
    segment_budgets,
)
from lookahead.planning.heuristic.profile_build import build_profile, state_at_s
from lookahead.planning.heuristic.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    end_state,
)

#: time scalings g of the limits tried for a brake, smallest first
BRAKE_SCALES = (1.0, *np.geomspace(1.05, 20.0, 40))
#: fractions of the feed limit a brake aims at, tried in turn
BRAKE_TARGETS = (1.0, 0.7, 0.5, 0.3, 0.15, 0.05)
#: budget shrink factors tried for a brake that fails verification
BRAKE_SHRINK = (1.0, 0.85, 0.7, 0.5)


class BrakeRefusedError(PlanningError):
    """`Brake.brake` found no brake from the start state within the limits (the state
    itself cannot be brought within them, or every brake tried fails its check)."""


def time_scaled(limits: AxisLimits, g: float) -> AxisLimits:
    """Limits (v g, a g^2, j g^3): what the same motion needs when run g times faster."""
    return AxisLimits(limits.vmax * g, limits.amax * g * g, limits.jmax * g**3)


def state_scale(request: PlanRequest, grid: PathGrid) -> float:
    """The smallest time scaling g of the request's limits (v g, a g^2) that the start
    state's axis velocity and acceleration fit in (at the grid's first point)."""
    st = request.start
    xs, xss = grid.xs[0, 0], grid.xss[0, 0]
    lim = request.limits
    g_v = np.max(np.abs(xs * st.v) / lim.vmax)
    g_a = np.sqrt(np.max(np.abs(xss * st.v**2 + xs * st.a) / lim.amax))
    return float(max(g_v, g_a))


def phases_end(phases: Phases) -> PathState:
    """Position, feed and acceleration at the end of the last phase."""
    s, v, a = end_state(phases)
    return PathState(s, max(v, 0.0), a)


class Brake:
    """Brakes for one planner's shares and margin."""

    def __init__(self, shares: BudgetShares, margin: float, solver: SCurveSolver) -> None:
        self.shares = shares
        self.margin = margin
        self._solver = solver

    def brake(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
              limits: AxisLimits, fraction: float) -> tuple[Phases, float]:
        """The fastest feed change from the start state down to `fraction` of the feed
        limit and the scaling g it needed (coarse scan, then bisection). Verified at the
        grid points; raises PlanningError if no brake is found."""

        def fits(g: float) -> bool:
            return self._brake_at(request, grid, vlim, limits, g, 1.0, fraction) is not None

        st = request.start
        lo, hi = None, None
        for g in BRAKE_SCALES:
            if fits(g):
                hi = g
                break
            lo = g
        if hi is None:
            raise BrakeRefusedError(f"the start state (v={st.v:.6g}, a={st.a:.6g}) cannot be "
                                "brought within the limits")
        if lo is not None:
            for _ in range(12):  # the start fits from some g on: bisect for it
                mid = float(np.sqrt(lo * hi))
                lo, hi = (lo, mid) if fits(mid) else (mid, hi)
        # the brake is judged at the scaling the start state itself needs (1 if it is
        # within the request's limits): the budget model's conservatism gets no room
        check = time_scaled(request.limits,
                            max(1.0, state_scale(request, grid) * (1 + 1e-6)))
        for shrink in BRAKE_SHRINK:
            found = self._brake_at(request, grid, vlim, limits, hi, shrink, fraction)
            if found is None:
                break
            phases, ncell = found
            if not self._brake_fails(phases, grid, ncell, check):
                return phases, hi
        raise BrakeRefusedError(f"no brake within the limits from v={st.v:.6g}, a={st.a:.6g}")

    def stop_at(self, request: PlanRequest, grid: PathGrid, limits: AxisLimits,
                s_stop: float) -> tuple[Phases, float]:
        """A jerk-limited stop from the start state to rest at `s_stop` (a corner that the
        brakes to a fraction of the feed limit run through) and the scaling g it needed:
        the gentlest g of `BRAKE_SCALES` whose stop verifies at the grid points before
        s_stop (at the same limits as `brake`). Raises BrakeRefusedError if none does."""
        st = request.start
        ncell = min(max(int(np.searchsorted(grid.edges, s_stop, side="left")), 1),
                    grid.ncells)
        check = time_scaled(request.limits,
                            max(1.0, state_scale(request, grid) * (1 + 1e-6)))
        for g in BRAKE_SCALES:
            for shrink in BRAKE_SHRINK:
                phases = self._stop_at(request, grid, limits, g, shrink, ncell, s_stop)
                if phases is None:
                    break  # not at this scaling: a smaller budget does not help
                if not self._brake_fails(phases, grid, ncell, check):
                    return phases, g
        raise BrakeRefusedError(f"no stop at s={s_stop:.6g} within the limits from "
                                f"v={st.v:.6g}, a={st.a:.6g}")

    def _stop_at(self, request: PlanRequest, grid: PathGrid, limits: AxisLimits, g: float,
                 shrink: float, ncell: int, s_stop: float) -> Phases | None:
        """Stop phases to rest at s_stop under `limits` time-scaled by g (budgets times
        `shrink`, over the first `ncell` cells at a fixed-point bound of the stop's feed
        in each), or None if the start state does not fit or no forward stop exists."""
        st = request.start
        lim = time_scaled(limits, g)
        sub = first_cells(grid, ncell)
        feed = np.full(ncell, st.v)
        for _ in range(16):
            AJ = self._budgets(sub, feed, lim, shrink, st.a)
            if AJ is None:
                return None
            A, J = AJ
            # the feed's peak while a positive start acceleration runs out, as the cap
            V = max(float(np.max(feed)), st.v + max(st.a, 0.0) ** 2 / (2.0 * J)) * (1 + 1e-9)
            try:
                phases = self._solver.segment(st.s, s_stop - st.s, st.v, st.a, 0.0, V, A, J)
            except SegmentInfeasibleError:
                return None
            actual = _cell_feed_bound(phases, grid, ncell)
            if np.all(actual <= feed * (1 + 1e-9)):
                return phases
            feed = np.maximum(feed, actual)
        return None

    def _budgets(self, sub: PathGrid, feed: np.ndarray, lim: AxisLimits, shrink: float,
                 a0: float) -> tuple[float, float] | None:
        """The smallest path acceleration and jerk budgets (A, J) over the cells of `sub`
        at the feed bounds `feed` (one per cell), times `shrink`; A stretched by 1 / margin
        to admit the start acceleration a0. None if the start does not fit."""
        nb = BUDGET_FRACTIONS.size
        ncell = feed.size
        b = segment_budgets(sub, np.arange(ncell + 1), feed, lim, self.shares)
        A, J = float(np.min(b.A)), float(np.min(b.J)) * shrink
        A = max(A * shrink, min(A, abs(a0)))
        if abs(a0) > A and abs(a0) <= A / self.margin:
            A = abs(a0)
        fast = np.any(np.abs(sub.xs[:, :nb]) * feed[:, None, None] > lim.vmax)
        if fast or abs(a0) > A or not J > 0:
            return None
        return A, J

    def _brake_at(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                  limits: AxisLimits, g: float, shrink: float,
                  fraction: float) -> tuple[Phases, int] | None:
        """Brake phases under `limits` time-scaled by g (budgets times `shrink`) and the
        number of cells they cover, or None if the start state does not fit. The cells
        the brake runs over are found by fixed-point iteration (budgets -> length ->
        cells). The acceleration budget stretches by 1 / margin to admit the start
        acceleration (the brake is verified at the unmargined limits)."""
        st = request.start
        lim = time_scaled(limits, g)
        feed = np.array([st.v])  # an upper bound of the brake's feed in each cell
        for _ in range(16):
            ncell = feed.size
            # each cell its own "segment" at its own feed bound, then the smallest budgets
            AJ = self._budgets(first_cells(grid, ncell), feed, lim, shrink, st.a)
            if AJ is None:
                return None
            A, J = AJ
            target = min(float(np.min(vlim[:ncell])) * fraction, st.v)
            try:
                phases = self._solver.feed_change(st.s, st.v, st.a, target, A, J)
            except SegmentInfeasibleError:
                return None  # the fastest feed change would reverse
            if not phases.duration.size:
                return None  # already there: nothing a brake could change
            need = int(np.searchsorted(grid.edges, phases_end(phases).s, side="left"))
            need = min(max(need, 1), grid.ncells)
            actual = _cell_feed_bound(phases, grid, max(need, ncell))
            grown = np.concatenate([feed, actual[ncell:]])
            if need <= ncell and np.all(actual[:ncell] <= feed * (1 + 1e-9)):
                return phases, ncell
            feed = np.maximum(grown, actual)
        return None

    @staticmethod
    def _brake_fails(phases: Phases, grid: PathGrid, ncell: int, lim: AxisLimits) -> bool:
        """True if some axis exceeds `lim` at a grid point the brake passes."""
        s_end = phases_end(phases).s
        sub = first_cells(grid, ncell)
        inside = sub.s <= s_end
        v, a, j = (x.reshape(sub.s.shape)[:, :, None]
                   for x in state_at_s(build_profile(phases), sub.s.ravel()))
        vel = np.abs(sub.xs * v)
        acc = np.abs(sub.xss * v * v + sub.xs * a)
        jerk = np.abs(sub.xsss * v**3 + 3.0 * sub.xss * v * a + sub.xs * j)
        bad = (vel > lim.vmax) | (acc > lim.amax) | (jerk > lim.jmax)
        return bool(np.any(bad & inside[:, :, None]))


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


def first_cells(grid: PathGrid, ncell: int) -> PathGrid:
    """The grid cut to its first `ncell` cells."""
    return replace(grid, edges=grid.edges[:ncell + 1], s=grid.s[:ncell], xs=grid.xs[:ncell],
                   xss=grid.xss[:ncell], xsss=grid.xsss[:ncell],
                   jerk_scale=grid.jerk_scale[:ncell], c1_cap=grid.c1_cap[:ncell],
                   corner_after=grid.corner_after[:ncell])
