"""Rest-to-rest stretches of an LP plan, planned by another planner where it is faster.

Where a plan comes to rest at both ends of a stretch (the path's corners and the
near-reversals the LP's grid brings to rest, the job's start at rest, its end), the
fastest feed over that stretch depends on nothing outside it: any plan of the stretch that
passes the check may replace the LP's there. The LP loses on short, jerk-dominated
stretches, whatever its grid: c-polyline-deg1-30's first 8 mm move between two stops
takes 0.214 s on the LP's grid and on grids 2x, 4x and 8x finer (0.211-0.214 s; the
quintic between nodes overshoots the nodal jerk, which the jerk margin and the repairs
pay for), while the heuristic's S-curve (Ruckig, exact on a straight move) takes 0.168 s.

This module finds the stretches of a plan (`rest_spans`), swaps a stretch's time span in a
profile for another plan of it (`swap_spans`), and finds the kept stretch a replan starts
in (`splice_at`: its replan keeps the stretch's plan up to its end at rest and plans from
there). Arc lengths s in path units, times in seconds, q = (ds/dt)^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from lookahead.planning.base import FeedProfile, PathState, PlanRequest
from lookahead.planning.lp.rows import GridGeometry
from lookahead.planning.lp.seam import (
    REST,
    LastPlan,
    same_request_over,
    state_agrees,
    time_at,
)
from lookahead.planning.profile_ops import concatenate, slice_profile
from lookahead.planning.sampled_check import SampledRatios


@dataclass(frozen=True)
class Splice:
    """Another planner's plan of one rest-to-rest stretch: `request` from rest at its
    start.s to rest at its s_end, `geo` the LP's nodes over it (where a later path must
    agree with this one), `profile` the plan (time 0 at the stretch's start; None: that
    planner found none that passes the check), `used`: it replaced the LP's plan in the
    last plan that covered the stretch."""

    request: PlanRequest
    geo: GridGeometry
    profile: FeedProfile | None
    used: bool = False

    @property
    def s0(self) -> float:
        return float(self.request.start.s)

    @property
    def s1(self) -> float:
        return float(self.request.s_end)


def rest_spans(last: LastPlan, start_at_rest: bool, end_at_rest: bool) -> list[tuple[int, int]]:
    """Node index pairs (i, j), i < j, of consecutive rest nodes of `last`: its interior
    rest nodes (`stop_idx`), node 0 if the plan starts at rest and the last node if it ends
    at rest at the path's end (a window's end is not a rest: the next window moves on)."""
    rests = [int(i) for i in last.stop_idx]
    if start_at_rest:
        rests.append(0)
    if end_at_rest:
        rests.append(last.geo.n_nodes - 1)
    rests = sorted(set(rests))
    return list(pairwise(rests))


def node_times(last: LastPlan) -> np.ndarray:
    """Time (s) at each node of `last`, from its profile's start (one piece per interval)."""
    x = last.profile.s_of_t.x
    return x - x[0]


def swap_spans(profile: FeedProfile, spans: list[tuple[float, float, FeedProfile]]
               ) -> FeedProfile:
    """`profile` with each time span (t0, t1) (s from its start, in order, not overlapping)
    replaced by the given profile, which covers the same stretch of s from rest to rest."""
    parts, t = [], 0.0
    for t0, t1, stretch in spans:
        if t0 > t:
            parts.append(slice_profile(profile, t, t0))
        parts.append(stretch)
        t = t1
    if t < profile.duration:
        parts.append(slice_profile(profile, t))
    return concatenate(parts)


def interior_worst(ratios: SampledRatios, duration: float) -> float:
    """The worst ratio of a stretch's check over its samples strictly inside (0, duration):
    at its ends the feed is at rest on a corner of the path (or its start or end), where
    the path's derivatives are those of the piece on one side only (the next piece's at
    the end: the last S-curve phase's jerk, +jmax along this piece, was judged along the
    next one, 1.3x jmax on c-polyline-deg1-30); the jerk there is the neighbouring
    samples' own (constant in a phase)."""
    peaks = [float(r[(t > 0.0) & (t < duration)].max(initial=0.0)) for r, t in (
        (ratios.vel, ratios.t_vel), (ratios.acc, ratios.t_acc), (ratios.jerk, ratios.t_jerk))]
    return np.inf if any(np.isnan(p) for p in peaks) else max(peaks)


def state_matches(profile: FeedProfile, t: float, start: PathState) -> bool:
    """True if `profile` at time t is in the state `start` (`seam.state_agrees`, relative
    to the profile's peaks at its knots)."""
    pp = profile.s_of_t
    knots = pp.x
    v_scale = float(np.max(np.abs(pp.derivative()(knots))))
    a_scale = float(np.max(np.abs(pp.derivative(2)(knots))))
    _, v_t, a_t, _ = profile.at(np.array([t]))[:, 0]
    return state_agrees(start, v_t, a_t, v_scale, a_scale)


def applies(sp: Splice, request: PlanRequest) -> bool:
    """True if `sp` was planned for what `request` asks over the stretch: the same dt and
    limits, the same feed cap and path at the stretch's nodes."""
    return same_request_over(sp.request, request, sp.geo, slice(0, sp.geo.n_nodes))


def find_splice(splices: list[Splice], request: PlanRequest, s0: float, s1: float
                ) -> Splice | None:
    """The stretch [s0, s1] of `splices` planned for what `request` asks, if any."""
    tol = 1e-12 * max(abs(s1), 1.0)
    for sp in splices:
        if abs(sp.s0 - s0) <= tol and abs(sp.s1 - s1) <= tol and applies(sp, request):
            return sp
    return None


def splice_at(splices: list[Splice], request: PlanRequest) -> tuple[Splice, float] | None:
    """The used stretch whose plan the moving start of `request` lies on, and the time of
    that state in it; None if there is none: the start strictly inside the stretch, the
    window's end at or beyond the stretch's end, `applies`, the state the plan's own."""
    start = request.start
    if start.v <= REST:
        return None
    for sp in splices:
        if not (sp.used and sp.profile is not None and sp.s0 < start.s < sp.s1
                and request.s_end >= sp.s1 and applies(sp, request)):
            continue
        pp = sp.profile.s_of_t
        k = int(np.searchsorted(pp(pp.x), start.s, side="right")) - 1
        k = min(max(k, 0), pp.x.size - 2)
        t = time_at(sp.profile, k, start.s)
        if t is not None and state_matches(sp.profile, t, start):
            return sp, t
    return None
