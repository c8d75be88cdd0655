"""A committed plan on the sample clock, its verification, and the shortest stop.

Time is the sample index k (sample k is due at k*dt after the job's start). A `CommittedPlan`
anchors a `FeedProfile` at sample `k_plan` (profile time 0): sample k lies at profile time
(k - k_plan) * dt; from `k_end` on it holds its end state, at rest at `s_end`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

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
    #: samples k = cache_k0, cache_k0 + 1, ... computed once (`with_samples`)
    cache: Samples | None = field(default=None, compare=False, repr=False)
    cache_k0: int = 0
    #: the profile's raw (s, v, a) at samples k = cache_k0, ... (3, n): what `state` returns
    #: there, evaluated once for all samples (`FeedProfile.at` is pointwise, so a value does
    #: not depend on the other times evaluated with it)
    states: np.ndarray | None = field(default=None, compare=False, repr=False)
    #: the LP's start handed over through the heuristic's transient (`lp.handover`: t, s,
    #: share of the plan's time, whole), else None
    handover: dict | None = field(default=None, compare=False, repr=False)

    @classmethod
    def anchor(cls, path: Path, result: PlanResult, k_plan: int, dt: float) -> CommittedPlan:
        prof = result.profile
        s_end = float(prof.s_of_t(prof.s_of_t.x[-1]))
        k_end = k_plan + max(math.ceil(prof.duration / dt - 1e-9), 0)
        return cls(path, prof, k_plan, s_end, k_end, result.compute_s, result.method,
                   handover=result.info.get("handover"))

    def times(self, ks: np.ndarray, dt: float) -> np.ndarray:
        return (np.asarray(ks, dtype=float) - self.k_plan) * dt

    def samples(self, k0: int, n: int, dt: float) -> Samples:
        """Axis pos/vel/acc of samples k0 .. k0+n-1 (from the cache where it has them)."""
        c = self.cache
        if c is not None and self.cache_k0 <= k0 and k0 + n <= self.cache_k0 + len(c):
            sl = slice(k0 - self.cache_k0, k0 - self.cache_k0 + n)
            return Samples(c.pos[sl], c.vel[sl], c.acc[sl])
        return sample_profile(self.path, self.profile, self.times(np.arange(k0, k0 + n), dt))

    def _raw_states(self, lo: int, hi: int, dt: float) -> np.ndarray:
        """The profile's (s, v, a) at samples lo .. hi-1 (3, hi - lo), from `states`
        where it holds them."""
        st = self.states
        if st is not None and self.cache_k0 <= lo and hi <= self.cache_k0 + st.shape[1]:
            return st[:, lo - self.cache_k0:hi - self.cache_k0]
        return self.profile.at(self.times(np.arange(lo, hi), dt))[:3]

    def with_samples(self, dt: float, previous: CommittedPlan | None = None
                     ) -> tuple[CommittedPlan, int]:
        """This plan with its samples k_plan+1 .. k_end+3 computed once (the verification
        and every batch slice them; sampling 10 at a time cost ~2 ms per batch) and its
        path states there (`states`), and the first sample k_new that is not `previous`'s.

        Where this plan's path state (s, v, a) equals the cached `previous` plan's at the
        same samples (to rounding: a replan that continues its last plan, the LP's seams),
        those samples are the previous plan's, verified already; only samples from k_new
        on are computed."""
        k0, k1 = self.k_plan + 1, self.k_end + 4  # samples k0 .. k1 - 1
        raw = self.profile.at(self.times(np.arange(k0, k1), dt))
        mine_all = raw[:3]
        k_new = k0
        old = previous.cache if previous is not None else None
        if old is not None:
            assert previous is not None
            lo = max(k_new, previous.cache_k0)
            hi = min(k1, previous.cache_k0 + len(old), previous.k_end)
            if hi > lo:
                mine = mine_all[:, lo - k0:hi - k0]
                theirs = previous._raw_states(lo, hi, dt)
                tol = np.array([S_TOL * max(float(np.max(np.abs(theirs[0]))), 1.0),
                                1e-9 * (1.0 + float(np.max(np.abs(theirs[1])))),
                                1e-9 * (1.0 + float(np.max(np.abs(theirs[2]))))])
                same = np.all(np.abs(mine - theirs) <= tol[:, None], axis=0)
                if lo == k_new:
                    k_new = lo + (int(np.argmin(same)) if not np.all(same) else same.size)
        fresh = sample_profile(self.path, self.profile, self.times(np.arange(k_new, k1), dt),
                               raw[:, k_new - k0:])
        if k_new > k0:
            assert old is not None and previous is not None
            kept = slice(k0 - previous.cache_k0, k_new - previous.cache_k0)
            fresh = Samples(*(np.vstack([getattr(old, f)[kept], getattr(fresh, f)])
                              for f in ("pos", "vel", "acc")))
        return replace(self, cache=fresh, cache_k0=k0, states=mine_all), k_new

    def state(self, k: int, dt: float) -> PathState:
        """Path state (s, ds/dt, d2s/dt2) at sample k (end state from k_end on)."""
        if k >= self.k_end:
            return PathState(self.s_end)
        st = self.states
        if st is not None and 0 <= k - self.cache_k0 < st.shape[1]:
            s, v, a = st[:, k - self.cache_k0].tolist()
        else:
            s, v, a, _ = self.profile.at(np.array([(k - self.k_plan) * dt]))[:, 0].tolist()
        return PathState(s, max(v, 0.0), a)

    def s_at(self, k: int, dt: float) -> float:
        """`state(k, dt).s` (the same value) without building the state: the
        per-batch look-ahead test."""
        st = self.states
        i = k - self.cache_k0
        if k < self.k_end and st is not None and 0 <= i < st.shape[1]:
            return float(st[0, i])
        return self.state(k, dt).s

    def remaining_s(self, k: int, dt: float) -> float:
        """Motion time (s) from sample k to the plan's end."""
        return max(self.k_end - k, 0) * dt


def rest_plan(path: Path, s: float, k: int) -> CommittedPlan:
    """Stay at rest at arc length s from sample k on."""
    pp = PPoly(np.array([[0.0], [0.0], [0.0], [s]]), np.array([0.0, 1.0]))
    return CommittedPlan(path, FeedProfile(pp), k, s, k, 0.0, "rest")


def verify(plan: CommittedPlan, tail: np.ndarray, limits: AxisLimits, dt: float,
           k_new: int | None = None) -> str | None:
    """None if the published `tail` (last <= 3 positions) followed by the plan's samples
    up to rest passes the finite-difference checker at `limits`, else what failed.

    k_new: samples before it were verified already (`CommittedPlan.with_samples`): only
    the samples from k_new on are checked, with the 3 positions before them."""
    n = plan.k_end - plan.k_plan + 3
    pos = plan.samples(plan.k_plan + 1, n, dt).pos
    if tail.size:
        pos = np.vstack([tail, pos])
    if k_new is not None:
        first = pos.shape[0] - n + (k_new - plan.k_plan - 1)
        pos = pos[max(first - 3, 0):]
    report = check_positions(pos, limits, dt)
    if report.ok:
        return None
    return f"checker: {report.violations} violations, first {report.first}"


def plan_checked(planner: Planner, request: PlanRequest, k_plan: int, tail: np.ndarray,
                 check_limits: AxisLimits, previous: CommittedPlan | None = None
                 ) -> CommittedPlan:
    """Plan, anchor at k_plan and verify against the published tail; PlanningError if the
    planner fails, reports an unverified profile, misses the window or breaks a limit.
    previous: the plan in force (its samples are reused where the new plan equals it)."""
    result = planner.plan(request)
    if result.info.get("verified") is False:
        raise PlanningError(f"{planner.name}: profile not verified ({result.info})")
    plan, k_new = CommittedPlan.anchor(request.path, result, k_plan, request.dt).with_samples(
        request.dt, previous)
    tol = S_TOL * max(request.path.length, 1.0)
    if abs(plan.s_end - request.s_end) > 1e3 * tol:
        raise PlanningError(f"{planner.name}: profile ends at s={plan.s_end:.9g}, "
                            f"not at the window end {request.s_end:.9g}")
    problem = verify(plan, tail, check_limits, request.dt, k_new)
    if problem:
        raise PlanningError(f"{planner.name}: {problem}")
    return plan


def shortest_stop(planner: Planner, base: PlanRequest, k_plan: int, tail: np.ndarray,
                  check_limits: AxisLimits, s_max: float, iterations: int = 10,
                  rel_tol: float = 0.02) -> CommittedPlan | None:
    """The stop (to rest) nearest to base.start.s found by bisection on s_end in
    (start.s, s_max], at most `iterations` halvings and none once the bracket is within
    `rel_tol` of the stop distance; None if even s_max fails (the caller keeps its current
    plan, which already ends at rest at s_max).

    The tolerance trades a stop up to 2 % longer for time: the stop is computed while the
    machine runs on what is buffered, and the service buffers 1.5x its slowest computation
    ahead, which is what delays a hold. Measured on tube-9570 at full feed (LP plan): the
    halvings below 2 % were infeasible trials (~19 ms each against ~4 ms for a feasible
    one); the stop ends at 120.47 mm instead of 120.16-120.47 and takes 70 ms, not 106."""
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
        if hi - lo <= rel_tol * (hi - s0):
            break
        mid = 0.5 * (lo + hi)
        trial = attempt(mid)
        if trial is None:
            lo = mid
        else:
            best, hi = trial, mid
    return best
