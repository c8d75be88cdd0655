"""A moving start handed over through a jerk-limited transient (the last relaxation of the
LP from a moving start, before the caller's fallback).

A replan may start at a state the LP's grid cannot follow: one taken from a plan at the full
limits (the heuristic's, after a fallback or another planner's take-over), accelerating hard
where the path's curvature lowers the acceleration cap a few mm ahead, or braking into the
window's end. The LP's first node holds that state exactly, and its jerk rows between the
first nodes (mm apart) cannot express the jerk-limited ramp of the acceleration to 0 that
any continuation must begin with: the repairs stall at 1.5-7x jmax within a few mm of the
start (issue 13, `bench/replan_continuity.py --states-from heuristic`: 80 of 700 failed).

The transient planner (the heuristic, Ruckig S-curves, which plans from any state) plans
the same request; its plan's path acceleration reaches 0 where the start's transient ends
(the start of a cruise, a rest point, or a change from rising to braking). The LP then plans
from that state, which its first node and slope row hold exactly, and the plan is the
transient's head followed by the LP's plan: continuous in s, v and a (the acceleration is 0
on both sides), with a jump of the path jerk only, each side within the limits. The
earliest such state whose LP plans is used, at most `MAX_HANDOVERS` of them.

A transient that never reaches a = 0 before its end is a stop the start is committed to
(the braking into the window's end, seconds or milliseconds of it): its feed falls all the
way, so the LP's only freedom would be to brake later, harder than the S-curve's budget;
that stop is the plan (`whole`). Anything else raises the LP's own error, for the caller's
fallback. Times in seconds from the request's start, arc lengths in path units.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from lookahead.planning.base import (
    FeedProfile,
    PathState,
    Planner,
    PlanningError,
    PlanRequest,
    PlanResult,
)
from lookahead.planning.profile_ops import concatenate, slice_profile

#: LP attempts at the transient's zero-acceleration states, earliest first (each one LP
#: plan, only after the one before failed). Measured on the fast corpus's states of
#: heuristic plans (bench/replan_continuity.py --states-from heuristic): the first state
#: planned in all 33 transient handovers; the later ones only cost where no plan follows
MAX_HANDOVERS = 3
#: a zero of the acceleration closer than this to either end of the transient is its end
#: state, not a handover (s; below the 1 ms sample time by 1e3)
EDGE_S = 1e-6
#: a committed stop ends with a feed below this fraction of its start feed (at least of
#: 1 path unit / s): at rest, to rounding
REST_TOL = 1e-9


def zero_acceleration_times(profile: FeedProfile) -> np.ndarray:
    """Times (s, from the profile's start) where its path acceleration is 0 inside it:
    sign changes and the starts of pieces of constant feed, earliest first."""
    pp = profile.s_of_t
    roots = pp.derivative(2).roots(extrapolate=False)
    t = np.unique(roots[np.isfinite(roots)]) - pp.x[0]
    return t[(t > EDGE_S) & (t < profile.duration - EDGE_S)]


def is_committed_stop(profile: FeedProfile) -> bool:
    """True if the profile brakes all the way to rest: its path acceleration has no zero
    inside it (it is continuous, so it keeps one sign), that sign is negative, and the feed
    at its end is 0 (to REST_TOL of the start feed)."""
    if zero_acceleration_times(profile).size:
        return False
    _, v, a, _ = profile.at(np.array([0.0, 0.5 * profile.duration, profile.duration]))
    return bool(a[1] < 0.0 and abs(v[2]) <= REST_TOL * max(abs(float(v[0])), 1.0))


def plan_handed_over(request: PlanRequest, transient: Planner,
                     plan_lp: Callable[[PlanRequest], PlanResult], error: PlanningError
                     ) -> PlanResult:
    """The request planned as the transient's head to its earliest zero-acceleration state
    whose LP (`plan_lp`) plans, then that LP plan; the transient whole if it is a committed
    stop; else `error` (the LP's failure from the start) is raised. info["handover"] says
    where (t, s, the share of the plan's time the transient took, `whole`, which state
    `attempt` planned, from 0) and why."""
    try:
        head = transient.plan(request)
    except PlanningError:
        raise error from None
    reason = str(error)
    for attempt, t in enumerate(zero_acceleration_times(head.profile)[:MAX_HANDOVERS]):
        state = head.profile.state_at(float(t))
        if not request.start.s < state.s < request.s_end:
            continue
        try:
            rest = plan_lp(replace(request, start=PathState(state.s, state.v, 0.0)))
        except PlanningError:
            continue
        profile = concatenate([slice_profile(head.profile, 0.0, float(t)), rest.profile])
        info = dict(rest.info)
        info["handover"] = {"t": float(t), "s": state.s, "v": state.v,
                            "share": float(t) / profile.duration, "whole": False,
                            "attempt": attempt, "reason": reason}
        return PlanResult(profile, rest.method, 0.0, info)
    if is_committed_stop(head.profile) and request.v_end == 0.0:
        info = {"verified": head.info.get("verified", True),
                "handover": {"t": head.profile.duration, "s": request.s_end, "v": 0.0,
                             "share": 1.0, "whole": True, "attempt": None,
                             "reason": reason}}
        return PlanResult(head.profile, "lp", 0.0, info)
    raise error
