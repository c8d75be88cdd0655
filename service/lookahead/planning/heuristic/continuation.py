"""Continuing the last plan: a replan that starts on the heuristic's last plan may keep
that plan up to its next cruise state (the seam) and plan from there.

Why: a replan from a state of the last plan plans on a new grid of cells and segments,
from a start the last plan reached by motions (valleys above the caps, rises onto a
short dip) that the new layout may not offer from that state; it then brakes, merges
its first segments or repairs for rounds, and crawls where the last plan did not
(cam-fp-hel25's replan 1.4 mm before a tight bend: 300 mm at 119 mm/s, 13.4 s over a
stretch the whole-job plan takes in 2.8 s; w-cone-R80to40's replan accelerating at
1197 mm/s^2 into a 6 mm dip: 4.40 s against 3.87). The LP keeps its last plan's nodes
at a seam for the same reason (`lp.seam`).

Frames and units: s arc length (path units), t seconds from a profile's start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lookahead.planning.base import FeedProfile, PathState, PlanRequest
from lookahead.planning.heuristic.path_limits import BudgetShares, build_grid
from lookahead.planning.heuristic.profile_build import state_at_s
from lookahead.planning.heuristic.verify import failing_cells, failing_phase_ends

#: a start matches a state of the last plan to this relative rounding (feed, acceleration)
MATCH_TOL = 1e-7
#: bisection steps for the time at which a profile passes an arc length (2^-60 of it)
TIME_STEPS = 60


@dataclass(frozen=True)
class LastPlan:
    """The request the planner last answered and the profile it returned."""

    request: PlanRequest
    profile: FeedProfile


def time_at_s(profile: FeedProfile, s: float) -> float:
    """The first time (s from the profile's start) at which the profile reaches arc
    length s (its end if it does not): bisection on the monotone s(t) (hand-written: one
    scalar inversion, which scipy's PPoly.solve answers with every root of every piece)."""
    pp = profile.s_of_t
    lo, hi = float(pp.x[0]), float(pp.x[-1])
    if not float(pp(hi)) > s:
        return hi - lo
    for _ in range(TIME_STEPS):
        mid = 0.5 * (lo + hi)
        if float(pp(mid)) < s:
            lo = mid
        else:
            hi = mid
    return hi - float(pp.x[0])


def start_time(last: LastPlan | None, request: PlanRequest) -> float | None:
    """The time on the last plan's profile at which the request's start is its state
    (same limits and dt; feed and acceleration to MATCH_TOL), or None. (A changed feed
    cap or path is for `prefix_within_limits` to judge.)"""
    if last is None or request.dt != last.request.dt or \
            not request.limits.same_as(last.request.limits):
        return None
    start = request.start
    prof = last.profile
    if not (start.v > 0.0 and last.request.start.s <= start.s < float(prof.s_of_t(
            prof.s_of_t.x[-1]))):
        return None
    t = time_at_s(prof, start.s)
    _, v, a, _ = prof.at(np.array([t]))[:, 0]
    v_scale = float(np.max(np.abs(prof.s_of_t.c[2]))) + 1.0
    a_scale = float(np.max(np.abs(prof.s_of_t.c[1]))) * 2.0 + 1.0
    if abs(v - start.v) > MATCH_TOL * v_scale or abs(a - start.a) > MATCH_TOL * a_scale:
        return None
    return t


def seam_time(profile: FeedProfile, t0: float, dt: float) -> float | None:
    """The first piece start of the profile at least one sample dt after t0 where the
    path acceleration is 0 and the feed positive (a cruise, the top of a rise, the
    start of the final brake), or None (only the rest at its end)."""
    pp = profile.s_of_t
    x = pp.x[:-1] - pp.x[0]
    acc = 2.0 * pp.c[1]
    vel = pp.c[2]
    a_scale = float(np.max(np.abs(acc))) + 1.0
    ok = (x >= t0 + dt) & (np.abs(acc) <= MATCH_TOL * a_scale) & (vel > 0.0)
    idx = np.nonzero(ok)[0]
    return None if idx.size == 0 else float(x[idx[0]])


def prefix_within_limits(request: PlanRequest, prefix: FeedProfile, shares: BudgetShares,
                         max_cell: float | None) -> bool:
    """The kept part of the last plan checked like a new plan on the request's own path,
    limits and caps (its grid's points, the finite differences around its phase ends, the
    feed cap and C1-knot caps at the points): a path or a cap that changed under it
    (streamed geometry, new segments' feeds) refuses it."""
    s0 = request.start.s
    s1 = float(prefix.s_of_t(prefix.s_of_t.x[-1]))
    if not s1 > s0:
        return False
    grid = build_grid(request.path, s0, s1, request.dt, request.limits, shares,
                      request.feed_cap, max_cell)
    cap = grid.c1_cap[:, None]
    if request.feed_cap is not None:
        cap = np.minimum(cap, request.feed_cap.at(grid.s))
    v = state_at_s(prefix, grid.s.ravel())[0].reshape(grid.s.shape)
    if np.any(v > cap * (1.0 + MATCH_TOL)):
        return False  # a feed cap or a C1-knot cap of the new request
    return not (failing_cells(prefix, grid, request.limits).any()
                or failing_phase_ends(request.path, prefix, grid, request.limits,
                                      request.dt).any())


def seam_state(profile: FeedProfile, t: float) -> PathState:
    """The profile's state at time t (path acceleration 0 there: `seam_time`)."""
    s, v, a, _ = profile.at(np.array([t]))[:, 0]
    return PathState(float(s), float(v), float(a))
