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
   and the motion from the restart to the next state is solved by Ruckig. Where that
   fails (the next state is out of reach from the cap within the segment), with feed
   levels: forward rises from the restart until Ruckig lands one on the scan (where a
   rise would overshoot it, over several segments from one of its last states), or one
   Ruckig motion over several segments, or forward rises from a restart below the cap;
   the zero-acceleration junction feeds (from which forward rises are tried once more)
   are the last resort.
2. Forward chain from the start state: in each segment the fastest rise (full acceleration
   towards V) is taken while it stays below the backward scan and can still reach the
   backward state one junction further (a Ruckig segment, kept for the next step);
   otherwise the kept Ruckig segment blends onto the backward scan (the switching point
   lies in that segment), or, with feed levels where faster, the segment's level rise up
   to where Ruckig can still land it on the scan (`_land_level_rise`), and the chain
   follows the scan's own motions until a rise fits again. If neither fits, the blend
   is moved a junction back (backtracking), at the start over several segments at once.
3. Valleys (`valley`, with feed levels): at a tight bend the backward scan takes a
   valley's motion over its span of segments where a motion from its exit reaches the
   scan's state after it, and goes on from its entry; nothing else writes into a span
   (restart rises land before it, merges do not cross it), and the chain follows the
   span's motion or backs out of it.
Rises are closed-form feed changes (`rise`: one budget, or the segment's feed levels
where given), blends are Ruckig
state-to-state segments (target feed and acceleration). Returns None when no chain is
found (the planner then falls back to zero junction accelerations or drops the layout).
"""

from __future__ import annotations

import numpy as np

from lookahead.planning.heuristic.levels import FeedLevels
from lookahead.planning.heuristic.path_limits import SegmentBudgets
from lookahead.planning.heuristic.profile_build import concat_phases
from lookahead.planning.heuristic.rise import rise as _rise
from lookahead.planning.heuristic.rise import rise_levels
from lookahead.planning.heuristic.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    latest_feasible,
    split_at,
)
from lookahead.planning.heuristic.valley import Valley

_REL = 1e-9  # relative feed tolerance when comparing a scan state with a cap
#: relative room on the cruise cap given to Ruckig (see `chain.solve`)
V_ROOM = 1e-7
#: most planning segments one blend may span when the switch lies beyond the next junction
MAX_MERGE = 8
#: most planning segments a forward rise after a restart may run before it lands on the
#: backward scan (a compute bound: on the B-spline corners, the near-cusp cycloid and the
#: butterfly every landing came within 15 segments, 90 % of failures within 5; 16 cost
#: the ellipse's fine layout 30 % (1.455 -> 1.894 s), 32 and 64 plan it alike)
MAX_ONTO = 32


def neighbour_min(x: np.ndarray) -> np.ndarray:
    """min(x[k-1], x[k], x[k+1]) per segment: the scans bring a junction state within
    the budgets of both segments it joins."""
    out = x.copy()
    out[1:] = np.minimum(out[1:], x[:-1])
    out[:-1] = np.minimum(out[:-1], x[1:])
    return out


def _level_rise(solver: SCurveSolver, levels: FeedLevels | None, k: int, nb: int | None,
                s0: float, L: float, v: float, a: float, V: float, A: float, J: float
                ) -> tuple[Phases, float, float] | None:
    """The rise of segment k towards V: under its feed levels (`rise.rise_levels`) where
    they apply and the end state lies within the budget of segment `nb` (the one the
    scan enters next), else under the single budget A."""
    if levels is not None and levels.tops[k][-1] <= V:
        got = rise_levels(s0, L, v, a, levels.tops[k], levels.accs[k], J)
        if got is not None and (nb is None
                                or abs(got[2]) <= levels.ceiling(nb, got[1]) * (1 + 1e-9)):
            return got
    return _rise(solver, s0, L, v, a, V, A, J)


def backward_scan(solver: SCurveSolver, b: SegmentBudgets, cap: np.ndarray, w: np.ndarray,
                  v_end: float, A: np.ndarray, J: np.ndarray, solve,
                  levels: FeedLevels | None = None, keep_first: bool = False,
                  first_curve: list | None = None, valleys: list[Valley] | None = None,
                  fixed: np.ndarray | None = None
                  ) -> tuple[np.ndarray, list[Phases | None]]:
    """(nseg + 1, 2) backward scan states (v, a) at the junctions (a forward in time), and
    per segment the scan's own motion from its state at k to the one at k + 1 (forward in
    time). Where the scan arrives above a cap it restarts at (cap, 0); if `solve` (a Ruckig
    segment) does not connect that to the state after, it restarts at (w, 0) instead, w the
    feeds that zero-acceleration S-curves connect (`zero_junctions.junction_feeds`), and the
    states after it fall back to (w, 0) until `solve` connects them, at worst all the way
    (the zero-acceleration chain). The scan's motions are the fastest
    decelerations: their states lie on the edge of what Ruckig finds feasible, so the
    chain uses these motions themselves rather than asking Ruckig again.

    `first_curve` (a list): receives the scan's fastest motion over segment 0 onto the
    state at junction 1 as it is before any cap (forward in time; nothing if it stops)
    and that state,
    where the chain lands a start state that lies inside it (`_land_in_first`).

    `valleys` (with levels): motions over spans of segments around tight bends
    (`valley.find_valleys`), whose exit junction's cap the caller raised to the next
    segment's (`raise_valley_caps`). Where the motion from a valley's exit onto the scan
    exists, the span takes the valley's states and motions (marked in `fixed`, which the
    chain then follows) and the scan goes on from its entry; else that cap is restored
    and the scan goes on as without it."""
    n = b.L.size
    after = {} if not valleys or levels is None else {v.k1 + 1: v for v in valleys}
    if fixed is None:
        fixed = np.zeros(n, dtype=bool)
    skip = -1  # segments k >= skip are a valley's, already filled
    out = np.zeros((n + 1, 2))
    out[n] = v_end, 0.0
    motions: list[Phases | None] = [None] * n
    soft = np.zeros(n + 1, dtype=bool)  # states from forward rises (`_rise_onto`)
    for k in range(n - 1, -1, -1):
        if k >= skip >= 0:
            continue
        vy = after.get(k)
        if vy is not None:
            if _take_valley(solver, b, cap, A, J, levels, solve, out, motions, soft, vy):
                fixed[vy.k0:vy.k1 + 1] = True
                skip = vy.k0
                continue
            cap[k] = vy.cap  # restored: as without the valley
        v, a = float(out[k + 1, 0]), -float(out[k + 1, 1])
        L, V, Ak, Jk, c = float(b.L[k]), float(b.V[k]), float(A[k]), float(J[k]), float(cap[k])
        got = _level_rise(solver, levels, k, k - 1 if k > 0 else None, 0.0, L, v, a, V, Ak,
                          Jk)
        if k == 0 and first_curve is not None and got is not None:
            first_curve.append((reversed_phases(got[0], float(b.s0[0]) + L),
                                (float(out[1, 0]), float(out[1, 1]))))
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
        if motions[k] is not None or (k == 0 and keep_first):
            # junction 0 is the start state: the forward chain reaches the scan from it
            # (or backtracks); lowering the scan to zero-acceleration feeds there would
            # hold the whole rise from the start at a = 0 junctions
            continue
        if levels is not None:
            args = (solver, b, cap, A, J, levels, solve, out, motions, soft, k, fixed)
            if _rises_onto(args, False) or _merge_onto(b, cap, solve, out, motions, k,
                                                       fixed):
                continue
            if _restart_lower(args, c, float(w[k])):
                continue
            out[k] = w[k], 0.0
            if _rises_onto(args, True):
                continue
        else:
            out[k] = w[k], 0.0
        for i in range(k, n):
            motions[i] = solve(i, out[i], out[i + 1])
            if motions[i] is not None or i + 1 == n or fixed[i + 1]:
                # (at a valley's entry the fallback stops: no chain; the planner plans
                # again without that valley. Given up in place, the zero-acceleration
                # feeds ran on over its span and beyond: butterfly, 17 % of junctions)
                break
            # the zero-acceleration feeds connect up to rounding at the exact
            # compatibility limit: lower the next one by a hair if Ruckig disagrees
            for shave in (0.0, 1e-9, 1e-7, 1e-5, 1e-3):
                out[i + 1] = w[i + 1] * (1.0 - shave), 0.0
                motions[i] = solve(i, out[i], out[i + 1])
                if motions[i] is not None:
                    break
    return out, motions


def _take_valley(solver: SCurveSolver, b: SegmentBudgets, cap: np.ndarray, A: np.ndarray,
                 J: np.ndarray, levels: FeedLevels, solve, out: np.ndarray, motions: list,
                 soft: np.ndarray, vy: Valley) -> bool:
    """In place: the valley `vy` in the backward scan, if a motion from its exit state
    (at junction k1 + 1) through segment k1 + 1 reaches the scan's state after (Ruckig, or
    forward rises onto the scan: `_rises_onto`); the span's states and motions are the
    valley's. False (nothing changed) otherwise."""
    n = b.L.size
    j = vy.k1 + 1
    saved = out.copy(), list(motions), soft.copy()
    out[j] = vy.exit
    ok = j == n
    if not ok:
        m = solve(j, out[j], out[j + 1])
        if m is not None:
            motions[j] = m
            ok = True
        else:
            ok = _rises_onto((solver, b, cap, A, J, levels, solve, out, motions, soft, j,
                              None), False)
    parts = _split_valley(b, vy) if ok else None
    if parts is None:
        out[:] = saved[0]
        motions[:] = saved[1]
        soft[:] = saved[2]
        return False
    out[vy.k0] = vy.entry
    for i, (part, state) in enumerate(parts):
        motions[vy.k0 + i] = part
        if state is not None:
            out[vy.k0 + i + 1] = state
    return True


def _split_valley(b: SegmentBudgets, vy: Valley) -> list | None:
    """The valley's motion split at the junctions inside its span: per segment its part
    and the state at its end (None for the last: the exit)."""
    motion = vy.phases
    parts = []
    for i in range(vy.k0 + 1, vy.k1 + 1):
        got = split_at(motion, float(b.s0[i]))
        if got is None:
            return None
        first, motion, v, a = got
        parts.append((first, (v, a)))
    parts.append((motion, None))
    return parts


#: restart feeds tried below a cap where no rise from the cap lands on the scan, as
#: fractions of the cap (above the zero-acceleration feed, the last resort): the rise from
#: a lower feed accelerates for longer before it meets a falling scan (butterfly: a
#: restart at 48 mm/s fell back to 19). More fractions: closer to the highest restart
#: that lands, for one `_rise_onto` each where the cap fails
RESTART_FRACTIONS = (0.9, 0.75, 0.55)


def _restart_lower(args: tuple, c: float, w: float) -> bool:
    """In place (via `_rise_onto`): the state at junction k (`args`) restarted at
    (f c, 0) for f in RESTART_FRACTIONS above w, the first whose forward rises land on the
    scan; False (the state left at the last try) if none does."""
    out, k = args[7], args[10]
    for f in RESTART_FRACTIONS:
        if not f * c > w:
            break
        out[k] = f * c, 0.0
        if _rises_onto(args, True):
            return True
    return False


def _merge_onto(b: SegmentBudgets, cap: np.ndarray, solve, out: np.ndarray, motions: list,
                k: int, fixed: np.ndarray | None = None) -> bool:
    """In place: one Ruckig motion from the restart state at junction k over segments
    k .. k + m - 1 onto the scan's state at junction k + m (m = 2 .. MAX_MERGE), split into
    per-segment motions and the states at the junctions between; False if none exists.
    (A scan state just after a short segment, decelerating hard above the cap before it,
    is reachable only by a motion over several segments.)"""
    n = b.L.size
    return any(_merge_span(b, cap, solve, out, motions, k, m, fixed)
               for m in range(2, min(MAX_MERGE, n - k) + 1))


def _merge_span(b: SegmentBudgets, cap: np.ndarray, solve, out: np.ndarray, motions: list,
                k: int, m: int, fixed: np.ndarray | None = None) -> bool:
    """In place: one Ruckig motion from the state at junction k over segments
    k .. k + m - 1 onto the state at junction k + m, split into per-segment motions and
    the states at the junctions between; False (nothing changed) if there is none. The
    motion must pass each junction within its cap (0 at a corner: no merge across it)."""
    if any(c <= 0.0 for c in cap[k + 1:k + m].tolist()):
        return False
    if fixed is not None and fixed[k:k + m].any():
        return False  # a valley's span keeps its motion
    motion = solve(k, out[k], out[k + m], m)
    if motion is None:
        return False
    parts, states = [], []
    for i in range(k + 1, k + m):
        got = split_at(motion, float(b.s0[i]))
        if got is None:
            return False
        first, motion, v, a = got
        if v > cap[i] * (1 + _REL):
            return False
        parts.append(first)
        states.append((v, a))
    parts.append(motion)
    for i, part in enumerate(parts):
        motions[k + i] = part
    for i, state in enumerate(states):
        out[k + 1 + i] = state
    return True


def _rises_onto(args: tuple, try_first: bool) -> bool:
    """`_rise_onto` passing above soft states, then (if it met one) staying below them."""
    got = _rise_onto(*args, try_first)
    if got is False:
        got = _rise_onto(*args, try_first, False)
    return bool(got)


def _rise_onto(solver: SCurveSolver, b: SegmentBudgets, cap: np.ndarray, A: np.ndarray,
               J: np.ndarray, levels: FeedLevels, solve, out: np.ndarray,
               motions: list, soft: np.ndarray, k: int, fixed: np.ndarray | None,
               try_first: bool, pass_soft: bool = True) -> bool | None:
    """In place: the states after a restart at junction k that Ruckig cannot connect to
    the scan's next state, from forward rises out of the restart state (fastest first, under
    the feed levels, gentler where the fastest would overshoot the scan's next states:
    `_land_gently`) until Ruckig lands one on the scan (where a rise cannot stay below it,
    over several segments: `_land_back`); False (nothing changed) if no rise does (None if
    it failed without passing a soft state). The forward-reachable states
    replace the zero-acceleration feeds the scan would otherwise fall back to (after a
    near-cusp they held the rise at a = 0 per segment).

    States written here are marked `soft`: they bound nothing (a later restart's rise,
    faster from further back, may pass above them; `pass_soft` False: it stays below them
    too); the rise must stay below the others. `try_first`: also try Ruckig from the
    restart state onto the next state first."""
    n = b.L.size
    saved = out.copy(), list(motions), soft.copy()
    x = (float(out[k, 0]), float(out[k, 1]))
    passed = False
    for i in range(k, min(n, k + MAX_ONTO)):
        if fixed is not None and fixed[i]:
            break  # rises land before a valley's span (its entry is a hard state)
        target = out[i + 1].copy()
        if i > k or try_first:
            m = solve(i, x, target)
            if m is not None:
                motions[i] = m
                return True
        if i + 1 == n:
            break
        Ji = float(J[i])
        got = _level_rise(solver, levels, i, i + 1, float(b.s0[i]), float(b.L[i]), x[0], x[1],
                          float(b.V[i]), float(A[i]), Ji)
        c_next = float(cap[i + 1])
        if got is not None and got[1] + got[2] * abs(got[2]) / (2.0 * Ji) > c_next * (1 + _REL):
            got = _rise(solver, float(b.s0[i]), float(b.L[i]), x[0], x[1],
                        min(float(b.V[i]), c_next), float(A[i]), Ji)
        hard = not (pass_soft and soft[i + 1])
        passed |= not hard
        if hard and got is not None and got[1] > target[0] * (1 + _REL):  # to the scan's feed
            got = _rise(solver, float(b.s0[i]), float(b.L[i]), x[0], x[1],
                        min(float(b.V[i]), float(target[0])), float(A[i]), Ji)
        if got is None or (hard and got[1] > target[0] * (1 + _REL)):
            if _land_back(b, cap, solve, out, motions, k, i, fixed):
                return True
            break
        if fixed is not None and fixed[i + 1]:
            break  # the next junction is a valley's entry: only landing on it (above)
        if i + 2 <= n and not (pass_soft and soft[i + 2]):
            got = _land_gently(solver, b, i, x, got, target, out[i + 2], A, J)
        out[i + 1] = got[1], got[2]
        soft[i + 1] = True
        motions[i] = got[0]
        x = (got[1], got[2])
    out[:] = saved[0]
    motions[:] = saved[1]
    soft[:] = saved[2]
    return False if passed else None


#: a forward rise of `_rise_onto` that overshoots the scan lands on it by one Ruckig motion
#: from one of its last LAND_BACK junction states onto one of the scan's next LAND_AHEAD
#: states (a compute bound: up to LAND_BACK * LAND_AHEAD Ruckig calls where a rise fails)
LAND_BACK, LAND_AHEAD = 4, 4


def _land_back(b: SegmentBudgets, cap: np.ndarray, solve, out: np.ndarray, motions: list,
               k: int, i: int, fixed: np.ndarray | None = None) -> bool:
    """In place: where the forward rise from the restart at junction k, at junction i,
    cannot stay below the scan, one Ruckig motion (`_merge_span`) from a rise state at a
    junction j in i, i - 1, ... (back to k) onto the scan's state at a junction after i;
    False if none exists. (The rise accelerates as hard as it may and meets a falling scan
    with too much acceleration to turn within one segment: after a restart below a
    near-cusp on the butterfly, the rise from the cap met the deceleration into it.)"""
    n = b.L.size
    for j in range(i, max(k, i - LAND_BACK + 1) - 1, -1):
        for t in range(i + 1, min(n, i + LAND_AHEAD) + 1):
            if (j, t) == (i, i + 1):
                continue  # tried by `_rise_onto` itself
            if _merge_span(b, cap, solve, out, motions, j, t - j, fixed):
                return True
    return False


def _land_gently(solver: SCurveSolver, b: SegmentBudgets, i: int, x: tuple[float, float],
                 got: tuple[Phases, float, float], target: np.ndarray, after: np.ndarray,
                 A: np.ndarray, J: np.ndarray) -> tuple[Phases, float, float]:
    """A forward rise of `_rise_onto` in segment i, or instead the rise towards the scan's
    feed at junction i + 1 where the fast one arrives there with more acceleration than
    the feed left below the scan's next state (`after`, at i + 2) can absorb: its
    overshoot v + a^2 / (2 J) above that feed made the next step fail (butterfly: rises
    after a near-cusp broke off, and the scan fell back to zero-acceleration feeds for
    40 segments). The gentle rise is taken only where it overshoots less."""
    Jn = float(J[i + 1])
    over = got[1] + max(got[2], 0.0) ** 2 / (2.0 * Jn)
    if over <= float(after[0]) * (1 + _REL):
        return got
    gentle = _rise(solver, float(b.s0[i]), float(b.L[i]), x[0], x[1],
                   min(float(b.V[i]), float(target[0])), float(A[i]), float(J[i]))
    if gentle is None or gentle[1] > target[0] * (1 + _REL):
        return got
    return gentle if gentle[1] + max(gentle[2], 0.0) ** 2 / (2.0 * Jn) < over else got


#: landing points tried on the first segment's scan motion (fractions of its length,
#: earliest first: the earlier the start lands, the sooner it runs on the fastest motion)
LAND_FRACTIONS = tuple(np.linspace(0.0625, 1.0, 16)[:-1])


def _land_in_first(b: SegmentBudgets, curve: list, start: tuple[float, float],
                   onto_state: np.ndarray, solve) -> Phases | None:
    """A motion over segment 0 from the start state onto the state at junction 1: Ruckig
    from the start onto the backward scan's fastest motion at a point inside segment 0,
    then that motion to the segment's end; None if no landing point is reached.

    A replan's start often lies on the scan motion of the plan it came from: braking
    under the feed levels, which no single-budget Ruckig motion to junction 1 can follow
    (a brake to rest at a window's end: twice the acceleration at low feed). The replan's
    own scan passes a hair above or below it (its grid samples other points), so the
    start cannot take over the scan at junction 0 but lands on it soon after.
    `onto_state`: the scan's state at junction 1 (the curve must still end there)."""
    if not curve or curve[0][1] != (float(onto_state[0]), float(onto_state[1])):
        return None
    s0, L = float(b.s0[0]), float(b.L[0])
    for f in LAND_FRACTIONS:
        got = split_at(curve[0][0], s0 + f * L)
        if got is None:
            continue
        _, tail, v, a = got
        if not v > 0.0:
            continue
        onto = solve(0, start, (v, a), length=f * L)
        if onto is not None:
            return concat_phases([onto, tail])
    return None


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
                A: float, J: float, cap_next: float,
                levels: FeedLevels | None = None) -> tuple[Phases, float, float] | None:
    """The fastest rise in segment k from state x towards its V, or towards the next cap
    if it would arrive with more acceleration than it can shed below that cap; under the
    segment's feed levels where given."""
    s0, L, V = float(b.s0[k]), float(b.L[k]), float(b.V[k])
    got = _level_rise(solver, levels, k, k + 1 if k + 1 < b.L.size else None, s0, L,
                      x[0], x[1], V, A, J)
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


#: bisection steps for where a level rise hands over to the Ruckig motion that lands it
#: on the backward scan (`_land_level_rise`): the hand-over within 2^-LAND_STEPS of the
#: rise's length
LAND_STEPS = 10
#: the landing is tried only where the segment's lowest feed level allows this much more
#: acceleration than its single budget (else Ruckig's motion is as fast: a compute bound)
LAND_GAIN = 1.1


def _land_level_rise(solver: SCurveSolver, b: SegmentBudgets, k: int, level: Phases,
                     target: np.ndarray, A: float, J: float) -> Phases | None:
    """Segment k's rise under its feed levels (`level`, from its start state), followed
    up to the latest point from which a Ruckig motion over the rest of the segment (cap
    V, budgets A and J, at least the acceleration it starts with) lands on the backward
    scan's state `target` at junction k + 1: bisection on that point. None if no point
    past the start does. Where the rise would overshoot the scan, the single-budget
    Ruckig motion from the start held the segment's acceleration at its budget at the
    cruise cap (846 mm/s^2 on cam-fp-vonkarman's rises out of its turnarounds, where the
    levels allow 2500 below 360 mm/s and the windowed LP accelerates at 2450)."""
    s0, L = float(b.s0[k]), float(b.L[k])
    end = s0 + L
    V = float(b.V[k]) * (1.0 + V_ROOM)
    v1, a1 = float(target[0]), float(target[1])

    def land(s_cut: float) -> Phases | None:
        got = split_at(level, s_cut)
        if got is None or not got[2] > 0.0:
            return None
        head, _, v, a = got
        try:
            tail = solver.segment(s_cut, end - s_cut, v, a, v1, V, max(A, abs(a), abs(a1)),
                                  J, a1=a1)
        except SegmentInfeasibleError:
            return None
        return concat_phases([head, tail])

    return latest_feasible(land, s0, end, LAND_STEPS)[0]


def _failed(broken: list | None, k: int) -> None:
    """A chain that found no motion: the segment where it gave up, into `broken`."""
    if broken is not None:
        broken.append(k)
    return None


def chain(solver: SCurveSolver, b: SegmentBudgets, cap: np.ndarray, w: np.ndarray,
          start: tuple[float, float],
          v_end: float, A_first: float, J_scan: np.ndarray, A_scan: np.ndarray,
          levels: FeedLevels | None = None, valleys: list[Valley] | None = None,
          broken: list | None = None) -> tuple[list[Phases], dict] | None:
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
    spans: dict[tuple[int, int], float] = {}  # np.sum of b.L over k .. k + m - 1

    def solve(k: int, x0, x1, m: int = 1, length: float | None = None) -> Phases | None:
        """Segments k .. k + m - 1 as one Ruckig motion from state x0 to state x1 (over
        the first `length` of segment k only, where given)."""
        if m == 1:
            L, V, A, J = Ls[k], Vs[k], As[k], Js[k]
            if length is not None:
                L = length
        else:
            # numpy's sum and min over the slices, without numpy's per-call cost on a few
            # elements (min is exact; the sum is numpy's own, kept per span: `_land_back`
            # asks for the same spans again and again)
            L = spans.get((k, m))
            if L is None:
                L = spans[k, m] = float(np.sum(b.L[k:k + m]))
            V, A, J = min(Vs[k:k + m]), min(As[k:k + m]), min(Js[k:k + m])
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

    curve: list = []
    fixed = np.zeros(n, dtype=bool)  # segments on a valley's motion (`backward_scan`)
    bwd, bmot = backward_scan(solver, b, cap, w, v_end, A_sc, J_scan, solve, levels,
                              keep_first=levels is not None, first_curve=curve,
                              valleys=valleys, fixed=fixed)
    if fixed.any():
        stats["fixed"] = fixed
    if any(m is None for m in bmot[1:]):
        return _failed(broken, next(i for i in range(1, n) if bmot[i] is None))
    parts: list[Phases] = []
    states = [(float(start[0]), float(start[1]))]  # the state reached at each junction
    blend: Phases | None = None  # a known motion from states[k] to bwd[k + 1]
    k, steps, floor = 0, 0, 0  # floor: no backtracking below (a merged start)
    while k < n:
        steps += 1
        if steps > 4 * n + 16:
            return _failed(broken, k)
        x = states[k]
        if fixed[k] and x == (float(bwd[k, 0]), float(bwd[k, 1])):
            parts.append(bmot[k])  # on a valley's motion: follow it
            states.append((float(bwd[k + 1, 0]), float(bwd[k + 1, 1])))
            blend = bmot[k + 1] if k + 1 < n else None
            k += 1
            continue
        rise = None
        if fixed[k]:
            # off a valley's motion inside its span (its feed lies above the
            # segments' caps): no motion of the budgets; back out of the span
            blend = None
        else:
            # a deceleration beyond the segment's budget is the backward scan's, under its
            # feed levels: nothing rises faster from there (the scan is the fastest state),
            # and a rise would first need Ruckig to brake it (70 % of the rises on a dome)
            level = None  # the segment's rise under its feed levels, kept or not
            if k + 1 < n and not (levels is not None and x[1] < -float(A_seg[k])):
                rise = _rise_below(solver, b, k, x, float(A_seg[k]), float(J_scan[k]),
                                   float(cap[k + 1]), levels)
                level = rise if levels is not None else None
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
                # and accelerates as late as possible): Ruckig's motion is used where it
                # exists
                blend = solve(k, x, bwd[k + 1]) or blend
            if blend is not None and blend is not bmot[k] and level is not None and \
                    levels.accs[k][0] > LAND_GAIN * As[k]:
                # (a single-budget Ruckig motion) or the level rise landed on the scan by
                # Ruckig, where faster
                landed = _land_level_rise(solver, b, k, level[0], bwd[k + 1],
                                          float(As[k]), float(Js[k]))
                if landed is not None and float(np.sum(landed.duration)) < float(
                        np.sum(blend.duration)):
                    blend = landed
                    stats["landed_levels"] = stats.get("landed_levels", 0) + 1
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
                    landed = _land_in_first(b, curve, states[0], bwd[1], solve)
                    if landed is None:
                        return _failed(broken, k)
                    parts = [landed]
                    states = [states[0], (float(bwd[1, 0]), float(bwd[1, 1]))]
                    k = floor = 1
                    blend = bmot[1] if n > 1 else None
                    stats["landed"] = 1
                    break
                parts = [blend]
                states = states[:1] + [tuple(x) for x in bwd[1:m + 1]]
                k = floor = m
                blend = bmot[k] if k < n else None
                stats["merged"] = m
                break
            if k <= floor or stats["backtracks"] > 4 * n:
                return _failed(broken, k)
            stats["backtracks"] += 1
            parts.pop()
            states.pop()
            k -= 1
            if fixed[k]:  # inside a valley's span: only its own motion
                on = states[k] == (float(bwd[k, 0]), float(bwd[k, 1]))
                blend = bmot[k] if on else None
            else:
                blend = solve(k, states[k], bwd[k + 1])
            if blend is not None:
                break
    return parts, stats
