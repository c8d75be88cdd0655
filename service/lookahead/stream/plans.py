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
from lookahead.planning.lp.profile import quintic_coefficients
from lookahead.sampling import Samples, sample_profile

#: relative tolerance on arc lengths (fraction of the path length, at least 1 unit)
S_TOL = 1e-9
#: `CommittedPlan.braking_from` looks for the final braking above this share of the plan's
#: peak feed: an LP window's plan crawls into its end (1.7 mm/s after braking from 100,
#: its acceleration swinging around 0), and the wiggle there put the real-time take-over
#: 0.3 s before the end, deep in the braking: dips to 5 mm/s mid-stroke (+0.6 % on
#: cam-feed-w3-F6000-L300-R100-a45-hoop, bench/corpus/gcode_feeds.py)
BRAKE_CRAWL_SHARE = 0.05


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

    def braking_from(self, dt: float) -> int:
        """The first sample of the plan's final braking: from it to k_end the path
        acceleration stays < 0 wherever the feed is above BRAKE_CRAWL_SHARE of the plan's
        peak (k_plan + 1 if the whole plan brakes)."""
        k0 = self.k_plan + 1
        if self.k_end <= k0:
            return k0
        _, v, a = self._raw_states(k0, self.k_end, dt)
        rising = np.flatnonzero((a >= 0.0) & (v > BRAKE_CRAWL_SHARE * float(np.max(v))))
        return k0 + (int(rising[-1]) + 1 if rising.size else 0)

    def braking_hard(self, ks: np.ndarray, dt: float, share: float) -> np.ndarray:
        """Whether the plan brakes at samples ks (before k_end) harder than `share` of its
        own strongest deceleration (path acceleration < -share max(-a) over the plan)."""
        k0 = self.k_plan + 1
        if self.k_end <= k0:
            return np.zeros(np.size(ks), dtype=bool)
        a_all = self._raw_states(k0, self.k_end, dt)[2]
        strongest = float(np.max(-a_all, initial=0.0))
        i = np.clip(np.asarray(ks) - k0, 0, a_all.size - 1)
        return (strongest > 0.0) & (a_all[i] < -share * strongest)

    def shifted(self, samples: int) -> CommittedPlan:
        """The same motion anchored `samples` later (its samples, cached ones included,
        depend only on k - k_plan)."""
        return replace(self, k_plan=self.k_plan + samples, k_end=self.k_end + samples,
                       cache_k0=self.cache_k0 + samples)

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
    guess = braking_guess(base.start.v, base.start.a,
                          float(np.min(base.limits.amax * base.path.path_scale)),
                          float(np.min(base.limits.jmax * base.path.path_scale)))
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


def braking_guess(v: float, a: float, acc: float, jerk: float) -> float:
    """A rough braking distance (path units) from path speed v and acceleration a at path
    acceleration and jerk limits acc, jerk: about twice the S-curve's from a cruise, more
    from an accelerating state."""
    return v * (v / acc + acc / jerk) + abs(a) ** 3 / jerk**2


def _polymul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Row-wise product of polynomials (ascending coefficients): (n, a) x (n, b) -> (n, a+b-1)."""
    out = np.zeros((p.shape[0], p.shape[1] + q.shape[1] - 1))
    for i in range(p.shape[1]):
        out[:, i:i + q.shape[1]] += p[:, i:i + 1] * q
    return out


def warped_profile(profile: FeedProfile, t0: float, ratio: float, ramp_s: float, dt: float,
                   flat_s: float = 0.0) -> tuple[FeedProfile, float]:
    """The profile from its time t0 on, run at a rate that ramps from 1 to `ratio` over
    `ramp_s` (profile time advances at r(tau) per unit of time tau; r has a constant
    second derivative, -, 0 and + over the ramp's first (ramp_s - flat_s) / 2, the next
    `flat_s` and the rest, so r' = 0 at both ends and constant in between), then at
    `ratio` to the end (`ratio` 0: a stop, at rest at the ramp's end or at the profile's
    end if that comes first): s_new(tau) = s(sigma(tau)), sigma(0) = t0, sigma' = r. Exact (a
    piecewise polynomial of degree 3 x the profile's), continuous in s, v, a (the jerk
    steps where r'' does); it starts in the profile's state at t0 and, after the ramp,
    is the profile time-scaled by `ratio`: within limits time-scaled by (ratio, ratio^2,
    ratio^3) of those the profile kept. Returns the profile and the ramp's end (its time).
    The ramp is stored as quintic Hermite pieces between the times k dt (`_quintic_hermite`:
    exact s, v, a there), the rest at the profile's own degree (at least 5)."""
    pp = profile.s_of_t
    x0 = float(pp.x[0])
    delta = 1.0 - ratio
    edge = 0.5 * (ramp_s - flat_s)  # the ramp's first and last phases
    c2 = delta / (edge * (edge + flat_s))  # |r''| there
    phases = [(edge, -c2), (flat_s, 0.0), (edge, c2)] if flat_s > 0 else [(edge, -c2),
                                                                         (edge, c2)]
    # r, r', r'', sigma at the starts of the ramp's phases and after it (`knots`)
    knots, r_k, dr_k, ddr_k, sig_k = [0.0], [1.0], [0.0], [], [0.0]
    for h, ddr in phases:
        ddr_k.append(ddr)
        sig_k.append(sig_k[-1] + r_k[-1] * h + 0.5 * dr_k[-1] * h**2 + ddr * h**3 / 6.0)
        r_k.append(r_k[-1] + dr_k[-1] * h + 0.5 * ddr * h**2)
        dr_k.append(dr_k[-1] + ddr * h)
        knots.append(knots[-1] + h)
    knots[-1], r_k[-1], dr_k[-1] = ramp_s, ratio, 0.0  # exact after the ramp
    ddr_k.append(0.0)
    knots, r_k, dr_k, ddr_k, sig_k = map(np.array, (knots, r_k, dr_k, ddr_k, sig_k))
    last = knots.size - 1  # the phase after the ramp

    def sigma(tau: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(knots, tau, side="right") - 1, 0, last)
        u = tau - knots[i]
        return sig_k[i] + r_k[i] * u + 0.5 * dr_k[i] * u**2 + ddr_k[i] * u**3 / 6.0

    # the times tau of the profile's breakpoints after t0 (sigma is increasing)
    bx = pp.x[1:] - x0
    bx = bx[bx > t0 + 1e-12]
    rel = bx - t0
    tau_b = np.empty_like(rel)
    after = rel >= sig_k[last]
    if ratio > 0.0:
        tau_b[after] = ramp_s + (rel[after] - sig_k[last]) / ratio
    inside = ~after
    if inside.any():
        lo, hi = np.zeros(int(inside.sum())), np.full(int(inside.sum()), ramp_s)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = sigma(mid) < rel[inside]
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        tau_b[inside] = 0.5 * (lo + hi)
    if ratio > 0.0 or not after.any():
        tau_end = float(tau_b[-1])  # the profile's end (the caller asks for t0 < its end)
    else:  # ratio 0, a stop: at rest at the ramp's end, before the profile's own end
        tau_b, tau_end = tau_b[inside], float(ramp_s)
    edges = np.unique(np.concatenate([[0.0], tau_b, knots[(knots > 0) & (knots < tau_end)],
                                      [tau_end]]))
    edges = edges[edges <= tau_end]
    a, b = edges[:-1], edges[1:]
    keep = b - a > 1e-15
    a = a[keep]
    edges = np.concatenate([a, [tau_end]])
    # on each interval: sigma(a + u) - x_i as a cubic in u; the profile's piece i there
    i_k = np.clip(np.searchsorted(knots, 0.5 * (edges[:-1] + edges[1:]), side="right") - 1,
                  0, last)
    u0 = a - knots[i_k]
    r_a = r_k[i_k] + dr_k[i_k] * u0 + 0.5 * ddr_k[i_k] * u0**2
    dr_a = dr_k[i_k] + ddr_k[i_k] * u0
    mid_t = t0 + sigma(0.5 * (edges[:-1] + edges[1:]))
    piece = np.clip(np.searchsorted(pp.x - x0, mid_t, side="right") - 1, 0, pp.c.shape[1] - 1)
    q = np.column_stack([t0 + sigma(a) - (pp.x[piece] - x0), r_a, 0.5 * dr_a,
                         ddr_k[i_k] / 6.0])
    # compose piece by piece at each part's own degree: in the ramp sigma is a cubic, after
    # it a line (the profile's own degree; a warp's padded zero rows stay exact zeros, so
    # warps in turn multiply the degree only where their ramps overlap)
    ramp_part = i_k < last
    parts = []
    for sel, width in ((ramp_part, 4), (~ramp_part, 2)):
        if not sel.any():
            parts.append(np.zeros((0, 1)))
            continue
        coef = pp.c[:, piece[sel]]  # descending powers
        nonzero = np.nonzero(np.any(coef != 0.0, axis=1))[0]
        coef = coef[nonzero[0]:] if nonzero.size else coef[-1:]
        out = coef[:1].T.copy()
        for k in range(1, coef.shape[0]):
            out = _polymul(out, q[sel, :width])
            out[:, 0] += coef[k]
        parts.append(out)
    degree = max(parts[0].shape[1], parts[1].shape[1]) - 1
    c = np.zeros((a.size, degree + 1))
    c[ramp_part, :parts[0].shape[1]] = parts[0]
    c[~ramp_part, :parts[1].shape[1]] = parts[1]
    exact = PPoly(np.ascontiguousarray(c[:, ::-1].T), edges)
    # the ramp re-expressed as quintic Hermite pieces between the sample times (s, v, a
    # exact there: the samples, and the states a replan starts from, are the warp's), so
    # that warps in turn (an operator turning the knob) do not multiply the degree
    n = math.ceil(ramp_s / dt - 1e-9)
    if n * dt >= tau_end - 1e-12:  # the profile ends within the ramp: Hermite to its end
        knots = np.arange(math.ceil(tau_end / dt - 1e-9)) * dt
        knots = np.concatenate([knots[knots < tau_end - 1e-9], [tau_end]])
        sva = np.stack([exact(knots, nu) for nu in range(3)])
        return (FeedProfile(PPoly(_quintic_hermite(sva, np.diff(knots)), knots)),
                float(tau_end))
    knots = np.arange(n + 1) * dt
    sva = np.stack([exact(knots, nu) for nu in range(3)])
    hermite = _quintic_hermite(sva, np.full(n, dt))
    cut = knots[-1]
    first = int(np.clip(np.searchsorted(edges, cut, side="right") - 1, 0, a.size - 1))
    d_post = parts[1].shape[1] - 1
    deg = max(5, d_post)
    # after the ramp: the profile's own degree; the piece cut at the last knot re-centred
    # there (its Taylor coefficients), the later pieces as they are
    piece_c = exact.c[exact.c.shape[0] - d_post - 1:, first]
    delta = cut - edges[first]
    taylor = [np.polyval(np.polyder(piece_c, nu), delta) / math.factorial(nu)
              if nu else np.polyval(piece_c, delta) for nu in range(d_post + 1)]
    n_post = a.size - first
    c_all = np.zeros((deg + 1, n + n_post))
    c_all[deg - 5:, :n] = hermite
    c_all[deg - d_post:, n] = taylor[::-1]
    if n_post > 1:
        c_all[deg - d_post:, n + 1:] = exact.c[exact.c.shape[0] - d_post - 1:, first + 1:]
    x_all = np.concatenate([knots, edges[first + 1:]])
    return FeedProfile(PPoly(c_all, x_all)), float(ramp_s)


def _quintic_hermite(sva: np.ndarray, h: np.ndarray) -> np.ndarray:
    """PPoly coefficients (6, n), descending powers, of the quintic pieces between n + 1
    knots (`h`: the n time spacings) that take the (s, v, a) of `sva` (3, n + 1) at both
    ends (the LP's interval quintic, `lp.profile.quintic_coefficients`)."""
    s0, v0, a0 = sva[:, :-1]
    s1, v1, a1 = sva[:, 1:]
    c3, c4, c5 = quintic_coefficients(h, s1 - s0, v0, a0, v1, a1)
    return np.stack([c5, c4, c3, 0.5 * a0, v0, s0])
