"""Free junction states by a backward jerk-limited scan and a forward chain of rises
(critical points), one motion per planning segment.

Units: path units (mm) and seconds. Segment k covers [s0[k], s0[k] + L[k]] under a cruise
cap V[k], acceleration budget A[k] and jerk budget J[k] (`path_limits.SegmentBudgets`);
junction k is the start of segment k (junction nseg is the window's end) and has a feed cap
(the lower V of its neighbours, 0 at a corner).

1. Backward scan: from the end state backwards in time, in each segment the fastest rise
   towards its V (a deceleration seen backwards), cut where the segment ends: the fastest
   state at each junction from which the rest can still be followed. Where it arrives
   above a cap it restarts there at (cap, 0) (a critical point of the feed-limit curve),
   and the motion from the restart to the next state is solved by Ruckig; where even that
   fails it falls back to the zero-acceleration junction feeds.
2. Forward chain from the start state: in each segment the fastest rise (full acceleration
   towards V) is taken while it stays below the backward scan and can still reach the
   backward state one junction further (a Ruckig segment, kept for the next step);
   otherwise the kept Ruckig segment blends onto the backward scan (the switching point
   lies in that segment) and the chain follows the scan's own motions until a rise fits
   again. If neither fits, the blend is moved a junction back (backtracking), at the start
   over several segments at once.
Rises are closed-form feed changes (`scurve.feed_change_phases`), blends are Ruckig
state-to-state segments (target feed and acceleration). Returns None when no chain is
found (the planner then falls back to zero junction accelerations or drops the layout).
"""

from __future__ import annotations

import numpy as np

from lookahead.planning.heuristic.path_limits import SegmentBudgets
from lookahead.planning.heuristic.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    cut_at,
    cut_lists,
    feed_change_lists,
)

_REL = 1e-9  # relative feed tolerance when comparing a scan state with a cap
#: relative room on the cruise cap given to Ruckig (see `chain.solve`)
V_ROOM = 1e-7
#: most planning segments one blend may span when the switch lies beyond the next junction
MAX_MERGE = 8


def neighbour_min(x: np.ndarray) -> np.ndarray:
    """min(x[k-1], x[k], x[k+1]) per segment: the scans bring a junction state within
    the budgets of both segments it joins."""
    out = x.copy()
    out[1:] = np.minimum(out[1:], x[:-1])
    out[:-1] = np.minimum(out[:-1], x[1:])
    return out


def _rise(solver: SCurveSolver, s0: float, L: float, v: float, a: float, V: float,
          A: float, J: float) -> tuple[Phases, float, float] | None:
    """The fastest rise from (v, a) towards V over length L, cut at s0 + L."""
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


def backward_scan(solver: SCurveSolver, b: SegmentBudgets, cap: np.ndarray, w: np.ndarray,
                  v_end: float, A: np.ndarray, J: np.ndarray, solve
                  ) -> tuple[np.ndarray, list[Phases | None]]:
    """(nseg + 1, 2) backward scan states (v, a) at the junctions (a forward in time), and
    per segment the scan's own motion from its state at k to the one at k + 1 (forward in
    time). Where the scan arrives above a cap it restarts at (cap, 0); if `solve` (a Ruckig
    segment) does not connect that to the state after, it restarts at (w, 0) instead, w the
    feeds that zero-acceleration S-curves connect (`zero_junctions.junction_feeds`), and the
    states after it fall back to (w, 0) until `solve` connects them, at worst all the way
    (the zero-acceleration chain). The scan's motions are the fastest
    decelerations: their states lie on the edge of what Ruckig finds feasible, so the
    chain uses these motions themselves rather than asking Ruckig again."""
    n = b.L.size
    out = np.zeros((n + 1, 2))
    out[n] = v_end, 0.0
    motions: list[Phases | None] = [None] * n
    for k in range(n - 1, -1, -1):
        v, a = float(out[k + 1, 0]), -float(out[k + 1, 1])
        L, V, Ak, Jk, c = float(b.L[k]), float(b.V[k]), float(A[k]), float(J[k]), float(cap[k])
        got = _rise(solver, 0.0, L, v, a, V, Ak, Jk)
        if got is not None and got[1] + got[2] * abs(got[2]) / (2.0 * Jk) > c * (1 + _REL):
            got = _rise(solver, 0.0, L, v, a, min(V, c), Ak, Jk)
        if got is not None and got[1] <= c * (1 + _REL):
            out[k] = got[1], -got[2]
            motions[k] = reversed_phases(got[0], float(b.s0[k]) + L)
            continue
        # arrives above the cap: restart at (cap, 0); what follows must then be reached
        # from there, so later states fall back to (cap, 0) until Ruckig connects
        out[k] = c, 0.0
        motions[k] = solve(k, out[k], out[k + 1])
        if motions[k] is not None:
            continue
        out[k] = w[k], 0.0
        for i in range(k, n):
            motions[i] = solve(i, out[i], out[i + 1])
            if motions[i] is not None or i + 1 == n:
                break
            # the zero-acceleration feeds connect up to rounding at the exact
            # compatibility limit: lower the next one by a hair if Ruckig disagrees
            for shave in (0.0, 1e-9, 1e-7, 1e-5, 1e-3):
                out[i + 1] = w[i + 1] * (1.0 - shave), 0.0
                motions[i] = solve(i, out[i], out[i + 1])
                if motions[i] is not None:
                    break
    return out, motions


def reversed_phases(ph: Phases, s_end: float) -> Phases:
    """A motion r(tau) backwards from s_end (r: distance travelled back, phases from r = 0)
    played forward in time: p(t) = s_end - r(T - t); feed and jerk keep their sign, the
    acceleration flips."""
    h, j, a, v, r = ph.duration, ph.jerk, ph.acc, ph.vel, ph.pos
    r_end = r + v * h + a * h * h / 2.0 + j * h**3 / 6.0
    v_end = v + a * h + j * h * h / 2.0
    a_end = a + j * h
    return Phases(h[::-1].copy(), j[::-1].copy(), -a_end[::-1], v_end[::-1],
                  s_end - r_end[::-1])


def _rise_below(solver: SCurveSolver, b: SegmentBudgets, k: int, x: tuple[float, float],
                A: float, J: float, cap_next: float) -> tuple[Phases, float, float] | None:
    """The fastest rise in segment k from state x towards its V, or towards the next cap
    if it would arrive with more acceleration than it can shed below that cap."""
    s0, L, V = float(b.s0[k]), float(b.L[k]), float(b.V[k])
    got = _rise(solver, s0, L, x[0], x[1], V, A, J)
    if got is not None and got[1] <= cap_next \
            and got[1] + got[2] * abs(got[2]) / (2.0 * J) > cap_next * (1 + _REL):
        got = _rise(solver, s0, L, x[0], x[1], min(V, cap_next), A, J)
    return got


#: a rise whose feed, with the overshoot its acceleration adds, stays below this fraction
#: of the backward scan at the next two junctions is taken without a Ruckig check (saves
#: one Ruckig call per segment while accelerating; backtracking covers the rare miss)
FAR_BELOW = 0.9


def _far_below(rise: tuple[Phases, float, float], b1: np.ndarray, b2: np.ndarray,
               J: float) -> bool:
    v, a = rise[1], rise[2]
    return v + a * abs(a) / (2.0 * J) <= FAR_BELOW * min(float(b1[0]), float(b2[0]))


def chain(solver: SCurveSolver, b: SegmentBudgets, cap: np.ndarray, w: np.ndarray,
          start: tuple[float, float],
          v_end: float, A_first: float, J_scan: np.ndarray, A_scan: np.ndarray
          ) -> tuple[list[Phases], dict] | None:
    """One motion per planning segment between free junction states (module doc).

    Invariant (where it can be kept): the state reached at junction k can reach the
    backward scan's state at k + 1 within segment k (a Ruckig motion kept as `blend`).
    `cap`: junction feed caps; `w`: zero-acceleration junction feeds (restart fallback);
    `A_first`: the first segment's acceleration budget (stretched to admit the start
    acceleration); `J_scan`, `A_scan`: the scans' budgets (`neighbour_min`). Returns the
    phases per segment and counts of rises, blends and backtracks, or None."""
    n = b.L.size
    A_seg = b.A.copy()
    A_seg[0] = max(A_seg[0], A_first)
    A_sc = A_scan.copy()
    A_sc[0] = max(A_sc[0], min(A_first, A_seg[0]))
    stats = {"rises": 0, "blends": 0, "backtracks": 0}
    s0s, Ls, Vs, As, Js = (x.tolist() for x in (b.s0, b.L, b.V, A_seg, b.J))

    def solve(k: int, x0, x1, m: int = 1) -> Phases | None:
        """Segments k .. k + m - 1 as one Ruckig motion from state x0 to state x1."""
        if m == 1:
            L, V, A, J = Ls[k], Vs[k], As[k], Js[k]
        else:
            sl = slice(k, k + m)
            L, V = float(np.sum(b.L[sl])), float(np.min(b.V[sl]))
            A, J = float(np.min(A_seg[sl])), float(np.min(b.J[sl]))
        A = max(A, abs(x0[1]), abs(x1[1]))
        # the scans' states sit exactly at the cap V (a rise towards V, cut): 1e-7 of room
        # keeps Ruckig's input check from refusing them by rounding (the velocity share
        # leaves 1e-4 to the limit)
        V *= 1.0 + V_ROOM
        try:
            return solver.segment(s0s[k], L, float(x0[0]), float(x0[1]), float(x1[0]), V, A,
                                  J, a1=float(x1[1]))
        except SegmentInfeasibleError:
            return None

    bwd, bmot = backward_scan(solver, b, cap, w, v_end, A_sc, J_scan, solve)
    if any(m is None for m in bmot[1:]):
        return None
    parts: list[Phases] = []
    states = [(float(start[0]), float(start[1]))]  # the state reached at each junction
    blend: Phases | None = None  # a known motion from states[k] to bwd[k + 1]
    k, steps, floor = 0, 0, 0  # floor: no backtracking below (a merged start)
    while k < n:
        steps += 1
        if steps > 4 * n + 16:
            return None
        x = states[k]
        rise = None
        if k + 1 < n:
            rise = _rise_below(solver, b, k, x, float(A_seg[k]), float(J_scan[k]),
                               float(cap[k + 1]))
            if rise is not None and rise[1] > bwd[k + 1, 0] * (1 + _REL):
                rise = None
        if rise is not None and _far_below(rise, bwd[k + 1], bwd[k + 2], Js[k]):
            parts.append(rise[0])  # no check needed yet (backtracking covers a miss)
            states.append((rise[1], rise[2]))
            blend, k = None, k + 1
            stats["rises"] += 1
            continue
        if rise is not None:
            nxt = solve(k + 1, (rise[1], rise[2]), bwd[k + 2])
            if nxt is not None:  # the rise keeps the invariant
                parts.append(rise[0])
                states.append((rise[1], rise[2]))
                blend, k = nxt, k + 1
                stats["rises"] += 1
                continue
        if blend is None or blend is bmot[k]:
            # the scan's own motion is feasible but not time-optimal (it holds the feed
            # and accelerates as late as possible): Ruckig's motion is used where it exists
            blend = solve(k, x, bwd[k + 1]) or blend
        if blend is not None:  # onto the backward scan
            parts.append(blend)
            states.append((float(bwd[k + 1, 0]), float(bwd[k + 1, 1])))
            blend = bmot[k + 1] if k + 1 < n else None
            k += 1
            stats["blends"] += 1
            continue
        if rise is not None:  # far below the backward scan: rise, no guarantee yet
            parts.append(rise[0])
            states.append((rise[1], rise[2]))
            k += 1
            stats["rises"] += 1
            continue
        # stuck: blend onto the backward scan one junction earlier
        while True:
            if k == floor and k == 0:  # from the start over several segments at once
                for m in range(2, min(MAX_MERGE, n) + 1):
                    blend = solve(0, states[0], bwd[m], m)
                    if blend is not None:
                        break
                if blend is None:
                    return None
                parts = [blend]
                states = states[:1] + [tuple(x) for x in bwd[1:m + 1]]
                k = floor = m
                blend = bmot[k] if k < n else None
                stats["merged"] = m
                break
            if k <= floor or stats["backtracks"] > 4 * n:
                return None
            stats["backtracks"] += 1
            parts.pop()
            states.pop()
            k -= 1
            blend = solve(k, states[k], bwd[k + 1])
            if blend is not None:
                break
    return parts, stats
