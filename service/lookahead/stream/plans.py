"""A committed plan on the sample clock, its verification, and the shortest stop.

Time is the sample index k (sample k is due at k*dt after the job's start). A `CommittedPlan`
anchors a `FeedProfile` at sample `k_plan` (profile time 0): sample k lies at profile time
(k - k_plan) * dt; from `k_end` on it holds its end state, at rest at `s_end`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PPoly

from lookahead.checker import check_positions
from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import (
    FeedProfile,
    PathState,
    Planner,
    PlanningError,
    PlanRequest,
    PlanResult,
)
from lookahead.sampling import Samples, sample_profile

#: relative tolerance on arc lengths (fraction of the path length, at least 1 unit)
S_TOL = 1e-9


@dataclass(frozen=True)
class CommittedPlan:
    """A profile on `path` anchored at sample `k_plan`; at rest at `s_end` from `k_end`."""

    path: Path
    profile: FeedProfile
    k_plan: int
    s_end: float
    k_end: int
    compute_s: float
    method: str

    @classmethod
    def anchor(cls, path: Path, result: PlanResult, k_plan: int, dt: float) -> CommittedPlan:
        prof = result.profile
        s_end = float(prof.s_of_t(prof.s_of_t.x[-1]))
        k_end = k_plan + max(math.ceil(prof.duration / dt - 1e-9), 0)
        return cls(path, prof, k_plan, s_end, k_end, result.compute_s, result.method)

    def times(self, ks: np.ndarray, dt: float) -> np.ndarray:
        return (np.asarray(ks, dtype=float) - self.k_plan) * dt

    def samples(self, k0: int, n: int, dt: float) -> Samples:
        """Axis pos/vel/acc of samples k0 .. k0+n-1."""
        return sample_profile(self.path, self.profile, self.times(np.arange(k0, k0 + n), dt))

    def state(self, k: int, dt: float) -> PathState:
        """Path state (s, ds/dt, d2s/dt2) at sample k (end state from k_end on)."""
        if k >= self.k_end:
            return PathState(self.s_end)
        s, v, a, _ = self.profile.at(np.array([(k - self.k_plan) * dt]))[:, 0]
        return PathState(float(s), max(float(v), 0.0), float(a))

    def remaining_s(self, k: int, dt: float) -> float:
        """Motion time (s) from sample k to the plan's end."""
        return max(self.k_end - k, 0) * dt


def rest_plan(path: Path, s: float, k: int) -> CommittedPlan:
    """Stay at rest at arc length s from sample k on."""
    pp = PPoly(np.array([[0.0], [0.0], [0.0], [s]]), np.array([0.0, 1.0]))
    return CommittedPlan(path, FeedProfile(pp), k, s, k, 0.0, "rest")


def verify(plan: CommittedPlan, tail: np.ndarray, limits: AxisLimits, dt: float) -> str | None:
    """None if the published `tail` (last <= 3 positions) followed by the plan's samples
    up to rest passes the finite-difference checker at `limits`, else what failed."""
    n = plan.k_end - plan.k_plan + 3
    pos = plan.samples(plan.k_plan + 1, n, dt).pos
    if tail.size:
        pos = np.vstack([tail, pos])
    report = check_positions(pos, limits, dt)
    if report.ok:
        return None
    return f"checker: {report.violations} violations, first {report.first}"


def plan_checked(planner: Planner, request: PlanRequest, k_plan: int, tail: np.ndarray,
                 check_limits: AxisLimits) -> CommittedPlan:
    """Plan, anchor at k_plan and verify against the published tail; PlanningError if the
    planner fails, reports an unverified profile, misses the window or breaks a limit."""
    result = planner.plan(request)
    if result.info.get("verified") is False:
        raise PlanningError(f"{planner.name}: profile not verified ({result.info})")
    plan = CommittedPlan.anchor(request.path, result, k_plan, request.dt)
    tol = S_TOL * max(request.path.length, 1.0)
    if abs(plan.s_end - request.s_end) > 1e3 * tol:
        raise PlanningError(f"{planner.name}: profile ends at s={plan.s_end:.9g}, "
                            f"not at the window end {request.s_end:.9g}")
    problem = verify(plan, tail, check_limits, request.dt)
    if problem:
        raise PlanningError(f"{planner.name}: {problem}")
    return plan


def shortest_stop(planner: Planner, base: PlanRequest, k_plan: int, tail: np.ndarray,
                  check_limits: AxisLimits, s_max: float, iterations: int = 10
                  ) -> CommittedPlan | None:
    """The stop (to rest) nearest to base.start.s found by bisection on s_end in
    (start.s, s_max]; None if even s_max fails (the caller keeps its current plan, which
    already ends at rest at s_max)."""
    s0 = base.start.s
    if base.start.v <= 0 and abs(base.start.a) <= 0:
        return rest_plan(base.path, s0, k_plan)

    def attempt(s_end: float) -> CommittedPlan | None:
        req = PlanRequest(base.path, base.limits, base.start, s_end, 0.0, base.feed_cap, base.dt)
        try:
            return plan_checked(planner, req, k_plan, tail, check_limits)
        except (PlanningError, ValueError, RuntimeError):
            return None

    # a first guess from the path-level limits: S-curve braking distance at the smallest
    # axis acceleration/jerk (a scalar formula, not worth a solver)
    v = base.start.v
    a_min = float(np.min(base.limits.amax * base.path.path_scale))
    j_min = float(np.min(base.limits.jmax * base.path.path_scale))
    guess = v * (v / a_min + a_min / j_min) + abs(base.start.a) ** 3 / j_min**2
    lo, hi = s0, s_max
    best = None
    if s0 + guess < s_max:
        trial = attempt(s0 + guess)
        if trial is not None:
            best, hi = trial, s0 + guess
        else:
            lo = s0 + guess
    if best is None:
        best = attempt(hi)
        if best is None:
            return None
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        trial = attempt(mid)
        if trial is None:
            lo = mid
        else:
            best, hi = trial, mid
    return best
