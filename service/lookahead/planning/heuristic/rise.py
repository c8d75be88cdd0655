"""Rises: the fastest jerk-limited feed change within one planning segment, cut where the
segment ends, under one acceleration budget or under budgets that depend on the feed
(`levels`).

Units: path units (mm) and seconds. A rise runs from a state (v, a) over [s0, s0 + L]
towards a feed V under |a| <= A, |j| <= J (`scurve.feed_change_lists`); a backward scan
uses the same rises with the acceleration's sign flipped (`scan.backward_scan`).
"""

from __future__ import annotations

import math

import numpy as np

from lookahead.planning.heuristic.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    cut_at,
    cut_lists,
    feed_change_lists,
)

_REL = 1e-9  # relative feed tolerance when comparing a feed with a cap


Rise = tuple[Phases, float, float]


def rise(solver: SCurveSolver, s0: float, L: float, v: float, a: float, V: float,
         A: float, J: float) -> Rise | None:
    """The fastest rise from (v, a) towards V over length L, cut at s0 + L: the phases and
    the feed and acceleration at the cut (None if the feed stops before it)."""
    if abs(v - V) <= _REL * V and abs(a) <= 1e-12 * max(A, 1.0):
        ph = Phases(np.array([L / v]), np.zeros(1), np.zeros(1), np.array([v]),
                    np.array([s0])) if v > 0 else None
        return (ph, v, 0.0) if ph is not None else None
    lists = feed_change_lists(s0, v, a, V, A, J)
    if lists is not None:
        return cut_lists(*lists, s0 + L)
    if abs(a) <= A:
        return None
    try:  # a start acceleration beyond the budget: Ruckig brakes it first
        phases = solver.feed_change(s0, v, a, V, abs(a), J)
    except SegmentInfeasibleError:
        return None
    return cut_at(phases, s0 + L) if phases.duration.size else None


def rise_levels(s0: float, L: float, v0: float, a0: float, tops: list[float],
                accs: list[float], J: float) -> Rise | None:
    """The fastest rise from (v0, a0) to tops[-1] under an acceleration budget that
    depends on the feed: accs[m] for feeds up to tops[m] (tops increasing, accs
    non-increasing: the centripetal terms grow with the feed), jerk J; cut at s0 + L.

    In the plane (v, q = a^2) a phase of jerk +J is a line of slope 2 J, a hold at a
    constant a a horizontal line and a phase of jerk -J a line of slope -2 J. The budget is
    the ceiling q <= accs[m]^2 on level m, lowered ahead of each step down by the -2 J line
    that reaches the next level's budget (or a = 0 at the top) just in time; the fastest
    rise climbs on its +J line until it meets the ceiling and then follows it. Written by
    hand: no library plans a 1-DOF motion under a feed-dependent acceleration limit.
    None if the start is outside what this covers (a0 < 0, v0 >= the top, a0 above the
    ceiling): the caller then uses `rise` with one budget."""
    V = tops[-1]
    if not (v0 < V and a0 >= 0.0 and J > 0.0 and min(accs) > 0.0):
        return None
    two_j = 2.0 * J
    # D[m]: the descending ceiling on level m is q <= D[m] - 2 J v (steps at levels >= m)
    n = len(tops)
    D = [0.0] * n
    nxt = two_j * V  # the final ramp to a = 0 at V
    for m in range(n - 1, -1, -1):
        if m < n - 1:
            nxt = min(nxt, accs[m + 1] ** 2 + two_j * tops[m])
        D[m] = nxt
    m = 0
    while m < n - 1 and v0 > tops[m]:
        m += 1
    q0 = a0 * a0
    # q tolerance: the lines D - 2 J v are differences of large numbers near the top (a
    # start 4e-14 below it met the final ramp's line at 0 by rounding)
    qtol = 1e-9 * accs[-1] ** 2 + 1e-12 * two_j * V
    if q0 > min(accs[m] ** 2, D[m] - two_j * v0) + qtol:
        return None  # above the ceiling: the caller uses one budget
    # pieces (jerk, a at start, a at end, v at start, v at end)
    pieces: list[tuple[float, float, float, float, float]] = []
    v, q = v0, q0
    climbing = q < min(accs[m] ** 2, D[m] - two_j * v) - qtol
    # walk the ceiling
    while m < n and v < V:
        hi = tops[m]
        qa = accs[m] ** 2
        v_line = (D[m] - qa) / two_j  # the hold at accs[m] meets the line here
        if climbing:
            # the +J line q + 2 J (x - v) meets the hold (at x_h) or the line (at x_l)
            x_h = v + (qa - q) / two_j
            x_l = v + (D[m] - two_j * v - q) / (2.0 * two_j)
            if x_h <= min(x_l, hi) and x_h <= v_line:
                pieces.append((J, math.sqrt(q), accs[m], v, x_h))
                v, q, climbing = x_h, qa, False
            elif x_l <= hi:
                x = max(x_l, v)
                q_new = q + two_j * (x - v)
                pieces.append((J, math.sqrt(q), math.sqrt(q_new), v, x))
                v, q, climbing = x, q_new, False
            else:
                q_new = q + two_j * (hi - v)
                pieces.append((J, math.sqrt(q), math.sqrt(q_new), v, hi))
                v, q = hi, q_new
                m += 1
                continue
        # on the ceiling: hold accs[m] up to v_line, then ramp down along the line
        if v < v_line and q >= qa - qtol:  # on the ceiling (the tolerance of `climbing`)
            x = min(v_line, hi)
            pieces.append((0.0, accs[m], accs[m], v, x))
            v, q = x, qa
            if x >= hi:
                m += 1
                climbing = False
                if m < n and q > min(accs[m] ** 2, D[m] - two_j * v) * (1.0 + 1e-9):
                    return None
                continue
        x = hi if m < n - 1 else V
        q_new = max(D[m] - two_j * x, 0.0)
        if m == n - 1:
            q_new = 0.0
        pieces.append((-J, math.sqrt(max(q, 0.0)), math.sqrt(q_new), v, x))
        v, q = x, q_new
        m += 1
        climbing = m < n and q < accs[m] ** 2 and q < D[m] - two_j * v
    return _cut_pieces(s0, v0, pieces, s0 + L, V)


def _cut_pieces(s0: float, v0: float, pieces: list, s_cut: float, V: float) -> Rise | None:
    """Phases from (jerk, a0, a1, v0, v1) pieces, cut at s_cut (cruise at V after)."""
    h, jk, ac, ve, po = [], [], [], [], []
    s = s0
    for j, a_s, a_e, v_s, v_e in pieces:
        d = (a_e - a_s) / j if j != 0.0 else (v_e - v_s) / a_s if a_s > 0.0 else 0.0
        if not d > 0.0:
            continue
        h.append(d)
        jk.append(j)
        ac.append(a_s)
        ve.append(v_s)
        po.append(s)
        s += v_s * d + a_s * d * d / 2.0 + j * d ** 3 / 6.0
    if not h:
        return None
    # the end feed is V with a = 0 up to rounding: cut_lists cruises on at the end feed
    return cut_lists(h, jk, ac, ve, po, s_cut)
