"""Where an LP replan continues the planner's last plan (a "seam").

The service replans from the state of a published sample, which lies on the plan in
force. The LP keeps that plan's grid, tightening and q up to a seam node and solves only
the rest (`lp.planner.LPPlanner.plan`). This module finds the seam (`find_seam`), checks that a
new path object agrees with the old one where nodes are reused (`same_stretch`: the
streaming fit hands out a new object whenever points arrive, with its final part
unchanged), and joins a kept head of the last plan to a new tail (`join_last`).
Arc lengths s are in path units, times in seconds, q = (ds/dt)^2.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import PPoly

from lookahead.geometry.base import Path
from lookahead.planning.base import FeedProfile, PathState, PlanRequest
from lookahead.planning.lp.envelope import braking_distance, path_limits
from lookahead.planning.lp.rows import GridGeometry, Tightening, velocity_caps
from lookahead.planning.profile_ops import concatenate

#: feeds below this (path units / s) count as rest
REST = 1e-9
#: q fixed at a seam: velocity, acceleration and jerk of the first interval (DESIGN.md)
FIXED_NODES = 3
#: a new path agrees with the old one at a reused node if positions and s-derivatives
#: differ by at most this, relative to (1 + |value|) (the streaming fit's final part is
#: bit-identical; a composite of the same pieces rounds its arc-length offsets)
AGREE_TOL = 1e-9
#: a replan's start state is a state of an earlier plan if its feed and path acceleration
#: differ by at most this, relative to 1 + that plan's peak feed and acceleration
STATE_TOL = 1e-7


@dataclass
class LastPlan:
    """The planner's last plan, kept for replans that start on it: the request, the grid
    geometry (from the node at or before its start), q, the node accelerations its profile
    used, the final tightening, the interior rest nodes and the profile before it was cut
    at the start (time 0 at geo.s[0])."""

    request: PlanRequest
    geo: GridGeometry
    q: np.ndarray
    a: np.ndarray
    tight: Tightening
    stop_idx: np.ndarray
    profile: FeedProfile


@dataclass
class Seam:
    """How a replan joins the last plan: its nodes 0..n_reuse-1 are the last plan's nodes
    first..first+n_reuse-1 (geometry, tightening and jerk linearization point reused), of
    which the first `FIXED_NODES` keep their q, so the first interval (cut at `t_cut`, s
    into it) is exactly the last plan's: velocity, acceleration and jerk continue."""

    last: LastPlan
    first: int
    n_reuse: int
    t_cut: float

    @property
    def reuses_all(self) -> bool:
        """True when the seam keeps every remaining node of the last plan (same end)."""
        return self.first + self.n_reuse == self.last.geo.n_nodes


def top_feed_reach(request: PlanRequest, geo: GridGeometry) -> float:
    """Braking distance (path units) from the top feed the velocity limits allow at the
    nodes of `geo`, at the path-level acceleration and jerk."""
    A, J = path_limits(request.path, request.limits)
    return braking_distance(float(np.sqrt(np.max(velocity_caps(geo, request.limits.vmax)))),
                            A, J)


def find_seam(last: LastPlan | None, request: PlanRequest) -> Seam | None:
    """The seam with `last` if the request starts on it while moving, else None.

    The request must use the same dt and limits, start at a state of the last plan (to
    rounding), and its path must agree with the last one on the reused nodes."""
    start = request.start
    if last is None or start.v <= REST:
        return None
    old = last.request
    s = last.geo.s
    i = int(np.searchsorted(s, start.s, side="right")) - 1
    if i < 0 or i >= s.size - 1:
        return None
    t_cut = time_at(last.profile, i, start.s)
    if t_cut is None:
        return None
    _, v, a, _ = last.profile.at(np.array([t_cut]))[:, 0]
    t_cut -= float(last.profile.s_of_t.x[i] - last.profile.s_of_t.x[0])
    if not state_agrees(start, v, a, float(np.sqrt(np.max(last.q))),
                        float(np.max(np.abs(last.a)))):
        return None
    if (abs(request.s_end - old.s_end) <= 1e-12 * max(abs(old.s_end), 1.0)
            and request.v_end == old.v_end):
        # the same end: the rest of the last plan is a solution, keep all its nodes
        n_reuse = s.size - i
    else:
        # reuse nodes up to one top-feed braking distance before the nearer window end
        # (there the last plan was already slowing down for its stop)
        reach = top_feed_reach(request, last.geo)
        k = int(np.searchsorted(s, min(old.s_end, request.s_end) - reach, side="right")) - 1
        n_reuse = max(k - i + 1, FIXED_NODES)
        if i + n_reuse >= s.size or s[i + n_reuse - 1] >= request.s_end:
            return None
    reused = slice(i, i + n_reuse)
    if not same_request_over(old, request, last.geo, reused):
        return None
    return Seam(last, i, n_reuse, t_cut)


def state_agrees(start: PathState, v: float, a: float, v_scale: float, a_scale: float
                 ) -> bool:
    """True if `start` has feed v and path acceleration a to STATE_TOL, relative to 1 +
    the peaks `v_scale`, `a_scale` of the plan they come from."""
    return (abs(v - start.v) <= STATE_TOL * (1.0 + v_scale)
            and abs(a - start.a) <= STATE_TOL * (1.0 + a_scale))


def same_request_over(old: PlanRequest, new: PlanRequest, geo: GridGeometry,
                      nodes: slice) -> bool:
    """True if `new` asks what `old` asked over the `nodes` of `geo`: the same dt and
    limits, the same feed cap (or none) and path there."""
    if new.dt != old.dt or not new.limits.same_as(old.limits):
        return False
    if new.feed_cap is not None or old.feed_cap is not None:
        s = geo.s[nodes]
        if (new.feed_cap is None or old.feed_cap is None
                or not np.array_equal(new.feed_cap.at(s), old.feed_cap.at(s))):
            return False
    return same_stretch(old.path, new.path, geo, nodes)


def same_stretch(old: Path, new: Path, geo: GridGeometry, nodes: slice) -> bool:
    """True if `new` has the positions and s-derivatives (1st..3rd) of `old` at the grid
    nodes geo.s[nodes] (`geo` sampled on `old`), to AGREE_TOL: the last plan's geometry,
    and so its profile, is valid on `new` there. The same object agrees without a look."""
    if new is old:
        return True
    s = geo.s[nodes]
    if s.size == 0 or new.length < s[-1] or geo.u is None:
        return False
    mine = geo.take(nodes)
    theirs = GridGeometry.sample(new, s)
    pos_old = old.eval_u(mine.u, 0)[0]
    pos_new = new.eval_u(theirs.u, 0)[0]
    pairs = ((pos_old, pos_new), (mine.d1, theirs.d1), (mine.d2, theirs.d2),
             (mine.d3, theirs.d3))
    return all(bool(np.all(np.abs(b - a) <= AGREE_TOL * (1.0 + np.abs(a)))) for a, b in pairs)


def join_last(last: LastPlan, first: int, stop: int, tail: LastPlan,
              request: PlanRequest) -> LastPlan:
    """The last plan's nodes first..stop-1 (and its profile over them) followed by `tail`
    (a plan starting at node `stop` of `last`, time 0 there), as one LastPlan of
    `request`."""
    kept = slice(first, stop)
    pp = last.profile.s_of_t
    head = FeedProfile(PPoly(pp.c[:, first:stop], pp.x[first:stop + 1], extrapolate=False))
    old_stops = last.stop_idx[(last.stop_idx > first) & (last.stop_idx < stop)] - first
    tight = replace(tail.tight, **{f: np.concatenate([getattr(last.tight, f)[kept],
                                                      getattr(tail.tight, f)])
                                   for f in ("vel", "acc", "jerk")})
    return LastPlan(
        request, GridGeometry.join(last.geo.take(kept), tail.geo),
        np.concatenate([last.q[kept], tail.q]), np.concatenate([last.a[kept], tail.a]),
        tight, np.concatenate([old_stops, tail.stop_idx + (stop - first)]).astype(int),
        concatenate([head, tail.profile]))


def time_at(profile: FeedProfile, piece: int, s: float) -> float | None:
    """The time (from the profile's start) at which piece `piece` of s(t) passes s, or
    None if it does not (the pieces are monotone: the feed is >= 0)."""
    pp = profile.s_of_t
    lo, hi = pp.x[piece], pp.x[piece + 1]
    one = PPoly(pp.c[:, piece:piece + 1], pp.x[piece:piece + 2], extrapolate=False)
    roots = one.solve(s, discontinuity=False, extrapolate=False)
    roots = roots[np.isfinite(roots)]
    if roots.size == 0:
        ends = np.array([lo, hi])
        k = int(np.argmin(np.abs(one(ends) - s)))
        if abs(float(one(ends[k])) - s) > 1e-9 * max(abs(s), 1.0):
            return None
        roots = ends[k:k + 1]
    return float(roots[0] - pp.x[0])
