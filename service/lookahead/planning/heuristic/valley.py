"""Valleys: a tight bend (a local minimum of the planning segments' cruise caps) passed by
one motion of constant positive path jerk over a span of segments instead of a cruise at
their caps; the backward scan restarts at the motion's entry and exit states and the
forward chain follows it (`scan.backward_scan`, `scan.chain`).

Why: a cruise (a = 0, j = 0) is bounded by |x_sss| v^3 <= share * jmax. On a plane curve
x_sss = kappa_s N - kappa^2 T, and the axis jerk x_sss v^3 + 3 x_ss v a + x_s j is
T (j - kappa^2 v^3) + N d(kappa v^3)/ds (with a = v dv/ds): a positive path jerk
j ~ kappa^2 v^3 cancels the tangential part, and a feed falling into the bend and rising
out of it (v ~ kappa^(-1/3) cancels it exactly) the normal part. The windowed LP passes
the butterfly's tightest bends at ~2x the heuristic's caps this way (path jerk up to
2.4 jmax at the apex).

A valley motion is v = vm + j0 t^2 / 2, a = j0 t around the apex (the tightest cell of the
segment at the minimum, t = 0 there), over the shortest span of segments at whose ends
it lies within the outer neighbours' caps and feed-level budgets and the scans' rises go
on from it (`_end_ok`); kept where the signed axis terms at every grid point of the span
stay within the limits, the feed within the feed cap and C1-knot caps, and it is faster
than cruising at the span's caps; the fastest apex feed, then the fastest such motion.
Fast corpus, heuristic / windowed LP: butterfly 1.548 -> 1.448, polar dome 1.219 ->
1.116, B-spline corners 1.264 -> 1.227, cam-style 1.023 -> 0.981.

A replan that starts inside a valley motion of the last plan starts above the caps, where
no motion of the budgets goes on from it: its valley is the motion's continuation from
the start state itself (`start_valley`, one phase of constant positive path jerk onto a
state within the caps past the apex). Units: path units (mm), seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.planning.heuristic.levels import FeedLevels
from lookahead.planning.heuristic.path_limits import BudgetShares, PathGrid, SegmentBudgets
from lookahead.planning.heuristic.profile_build import build_profile, state_at_s
from lookahead.planning.heuristic.reach import cubic_time_at
from lookahead.planning.heuristic.rise import rise_levels
from lookahead.planning.heuristic.scurve import Phases

#: apex feeds tried, as multiples of the segment's cruise cap, fastest first, and the
#: motion's jerk as fractions of kappa^2 vm^3 (the tangential cancellation): up to 15
#: candidates per valley, most refused at the apex cell. Fewer cost winding time: (2.0,
#: 1.5, 1.2) x (0.3, 1.0) butterfly 8.08 s against 7.96, dome 2.02 against 1.96 (fast
#: corpus, before MIN_GAP); jerks (0.2, 0.45) won 2.5 % on the dome, lost 1 % on the
#: butterfly
VM_FACTORS = (2.0, 1.7, 1.45, 1.25, 1.1)
JERK_FRACTIONS = (0.3, 0.6, 1.0)
#: a segment is a valley where its cap is below this fraction of both neighbours' caps
#: (0.9: butterfly 8.14 s against 7.96, corners 5.78 against 5.74; before MIN_GAP)
MIN_DEPTH = 0.95
#: planning segments kept between two valleys' spans (with one, the scan found no motion
#: from one valley's exit onto the next one's entry: butterfly s = 121)
MIN_GAP = 3


@dataclass(frozen=True)
class Valley:
    """A valley motion over planning segments k0 .. k1: its phases (forward in time),
    entry state (v1, a1) at junction k0 and exit state (v2, a2) at junction k1 + 1."""

    k0: int
    k1: int
    phases: Phases
    entry: tuple[float, float]
    exit: tuple[float, float]
    #: the exit junction's cap before `raise_valley_caps` (which fills it in)
    cap: float = 0.0


def _time_at(d: float, vm: float, j0: float) -> float:
    """The time t >= 0 with vm t + j0 t^3 / 6 = d (d >= 0)."""
    if not d > 0.0:
        return 0.0
    hi = d / vm
    return cubic_time_at(d, vm, 0.0, j0, hi, hi, 60, 1e-15 * hi)


#: relative room above a cell's hard bound before an apex feed is skipped unchecked
#: (`_best`): far above the rounding of the feed `_within_limits` evaluates there
_HARD_ROOM = 1e-9

#: most planning segments one valley motion spans (a bound on the span search: the caps
#: around a tight bend rise in bands of the band ratio; the butterfly's tightest apex,
#: s = 127.6, took 7 segments over 1.7 mm)
MAX_SPAN = 16


def find_valleys(grid: PathGrid, starts: np.ndarray, b: SegmentBudgets, levels: FeedLevels,
                 vlim: np.ndarray, cap: np.ndarray, limits: AxisLimits,
                 shares: BudgetShares, J: np.ndarray,
                 ban: np.ndarray | None = None,
                 hard: np.ndarray | None = None,
                 start: tuple[float, float] | None = None) -> list[Valley]:
    """Valley motions around the local minima of the caps (see the module doc), in
    order, their spans disjoint; `cap`: the junction caps (no span crosses a corner),
    `J`: the scans' jerk budgets, `ban`: segments no span (with its end neighbours)
    may touch (a valley the planner's verification refused), `hard`: per cell a feed
    bound no valley may pass (the feed cap, C1-knot caps; the segments' caps hold it
    too, but a valley runs above those), `start`: the start state (feed, acceleration),
    whose own valley (`start_valley`, above the first segment's cap) comes first."""
    n = b.L.size
    out: list[Valley] = []
    V = b.V
    last = 0  # no span reaches back before this segment
    if start is not None:
        first = start_valley(grid, starts, b, levels, cap, limits, shares, J, start, hard)
        if first is not None and not (ban is not None and ban[:first.k1 + 2].any()):
            out.append(first)
            last = first.k1 + 1 + MIN_GAP
    for k in range(1, n - 1):
        if not (V[k] < MIN_DEPTH * V[k - 1] and V[k] < MIN_DEPTH * V[k + 1]) or k < last:
            continue
        got = _best(grid, starts, b, levels, vlim, cap, limits, shares, J, k, last, hard)
        if got is not None and ban is not None and \
                ban[max(got.k0 - 1, 0):got.k1 + 2].any():
            got = None
        if got is not None:
            out.append(got)
            last = got.k1 + 1 + MIN_GAP
    return out


def _span(b: SegmentBudgets, levels: FeedLevels, J: np.ndarray, cap: np.ndarray, k: int,
          lo: int, s_m: float, vm: float, j0: float
          ) -> tuple[int, int, float, float, float, float] | None:
    """The shortest span k0 .. k1 around segment k whose ends the motion (vm, j0) about
    s_m crosses within the outer neighbours' caps and budgets (`_end_ok`): (k0, k1, t1,
    t2, then the entry and exit feeds), or None."""
    n = b.L.size
    k0 = k
    while True:
        t1 = _time_at(s_m - float(b.s0[k0]), vm, j0)
        v1 = vm + j0 * t1 * t1 / 2.0
        if _end_ok(b, levels, J, k0 - 1, v1, j0 * t1, float(cap[max(k0 - 1, 0)])):
            break
        k0 -= 1
        if k0 < max(lo, 1) or k - k0 >= MAX_SPAN or not cap[k0 + 1] > 0.0:
            return None
    k1 = k
    while True:
        t2 = _time_at(float(b.s0[k1] + b.L[k1]) - s_m, vm, j0)
        v2 = vm + j0 * t2 * t2 / 2.0
        if _end_ok(b, levels, J, k1 + 1, v2, j0 * t2, float(cap[min(k1 + 2, cap.size - 1)])):
            break
        k1 += 1
        if k1 > n - 2 or k1 - k0 >= MAX_SPAN or not cap[k1] > 0.0:
            return None
    if not (cap[k0] > 0.0 and cap[k1 + 1] > 0.0):
        return None  # the machine stops at a corner: no valley ends there
    return k0, k1, t1, t2, v1, v2


def _best(grid: PathGrid, starts: np.ndarray, b: SegmentBudgets, levels: FeedLevels,
          vlim: np.ndarray, cap: np.ndarray, limits: AxisLimits, shares: BudgetShares,
          J: np.ndarray, k: int, lo: int, hard: np.ndarray | None = None
          ) -> Valley | None:
    c0, c1 = int(starts[k]), int(starts[k + 1])
    apex = c0 + int(np.argmin(vlim[c0:c1]))
    s_m = float(grid.s[apex, 1])
    kappa = float(np.linalg.norm(grid.xss[apex, 1]))
    V = float(b.V[k])
    # the apex cell first (a few points, t ~ (s - s_m) / vm there): most candidates that
    # fail, fail there (the tangential residual), and the span search costs more
    ax_s = grid.s[apex] - s_m
    ax = (grid.xs[apex], grid.xss[apex], grid.xsss[apex])
    ax_jmax = limits.jmax * grid.jerk_scale[apex] * shares.headroom
    # the motion's feed at the apex point is vm: above the apex cell's hard bound,
    # `_within_limits` refuses every jerk of it (skipped before its span searches; a C1
    # path's knot caps make most of its cap minima such: c-rand3-xyz-pchip-1000pts, 2262
    # of 2534 searches, 2.8 s of the engine's 4.5 s; the same valleys)
    top = np.inf if hard is None else float(hard[apex]) * (1.0 + _HARD_ROOM)
    for f in VM_FACTORS:
        vm = f * V
        if vm > top:
            continue
        best: Valley | None = None
        best_t = np.inf
        for g in JERK_FRACTIONS:
            j0 = g * kappa * kappa * vm**3
            t = ax_s / vm
            va = (vm + j0 * t * t / 2.0)[:, None]
            aa = (j0 * t)[:, None]
            if np.any(np.abs(ax[2] * va**3 + 3.0 * ax[1] * va * aa + ax[0] * j0) > ax_jmax):
                continue
            span = _span(b, levels, J, cap, k, lo, s_m, vm, j0)
            if span is None:
                continue
            k0, k1, t1, t2, v1, v2 = span
            dur = t1 + t2
            cruise = float(np.sum(b.L[k0:k1 + 1] / b.V[k0:k1 + 1]))
            if not (dur < best_t and dur < cruise):
                continue
            a1 = -j0 * t1
            ph = Phases(np.array([dur]), np.array([j0]), np.array([a1]), np.array([v1]),
                        np.array([float(b.s0[k0])]))
            if not _within_limits(grid, int(starts[k0]), int(starts[k1 + 1]), ph, limits,
                                  shares, hard):
                continue
            best, best_t = Valley(k0, k1, ph, (v1, a1), (v2, j0 * t2)), dur
        if best is not None:
            return best
    return None


def _within_limits(grid: PathGrid, p0: int, p1: int, ph: Phases, limits: AxisLimits,
                   shares: BudgetShares, hard: np.ndarray | None) -> bool:
    """True if the one-phase motion `ph` keeps the signed axis velocity, acceleration and
    jerk within the limits (the budgets' velocity share and headroom; the jerk scaled
    next to C1 knots) at every grid point of cells p0 .. p1 - 1, and its feed within
    `hard` (per cell: feed cap, C1-knot caps; None: no such bound) there."""
    naxes = grid.xs.shape[2]
    xs, xss, xsss = (x[p0:p1].reshape(-1, naxes) for x in (grid.xs, grid.xss, grid.xsss))
    jmax = np.repeat(grid.jerk_scale[p0:p1], grid.s.shape[1])[:, None] * limits.jmax
    jmax = jmax * shares.headroom
    v, a = (x[:, None] for x in state_at_s(build_profile(ph), grid.s[p0:p1].ravel())[:2])
    if np.any(np.abs(xs * v) > limits.vmax * shares.velocity) or \
            np.any(np.abs(xss * v * v + xs * a) > limits.amax * shares.headroom):
        return False
    if hard is not None and np.any(v[:, 0] > np.repeat(hard[p0:p1], grid.s.shape[1])):
        return False
    return not np.any(np.abs(xsss * v**3 + 3.0 * xss * v * a + xs * float(ph.jerk[0]))
                      > jmax)


#: path jerks tried for a valley from the start state (`start_valley`), as multiples of
#: kappa^2 v0^3 (the tangential cancellation at the start feed v0 and the tightest
#: curvature kappa ahead), largest first: v(t) = v0 + a0 t + j t^2 / 2 grows with j at
#: every t, so the first that fits is the fastest. Trades the fit (steps of 1.27x: the jerk
#: taken is within 27 % of the largest that fits) against up to 20 span searches and grid
#: checks, only for starts above the first segment's cap. Measured on the polar dome's
#: replans from every 5th sample of its first valley (v0 = 82-108 mm/s, a0 = -600 .. +45
#: mm/s^2): the multiples taken lay in 0.10 .. 0.58, none at either end of the range
START_JERKS = tuple(float(x) for x in np.geomspace(4.0, 0.04, 20))


def start_valley(grid: PathGrid, starts: np.ndarray, b: SegmentBudgets, levels: FeedLevels,
                 cap: np.ndarray, limits: AxisLimits, shares: BudgetShares, J: np.ndarray,
                 start: tuple[float, float], hard: np.ndarray | None = None
                 ) -> Valley | None:
    """A valley motion from the start state (v0, a0) itself, or None: where a replan
    starts inside a valley motion of the last plan (above the first segment's cruise cap
    V[0], where no motion of the budgets goes on from it), that motion's continuation:
    one phase of constant path jerk j > 0 from the start over segments 0 .. k1, the
    shortest span whose exit state lies past the apex (a >= 0) and within segment
    k1 + 1's cap and budgets (`_end_ok`), checked at every grid point of the span like
    `find_valleys`' motions; the largest j of START_JERKS that fits (the fastest)."""
    v0, a0 = float(start[0]), float(start[1])
    n = b.L.size
    if not (n > 1 and v0 > float(np.min(b.V[:_braking_reach(b, v0, a0)]))):
        return None
    reach = int(starts[min(MAX_SPAN, n - 1)])
    kappa = float(np.max(np.linalg.norm(grid.xss[:reach], axis=-1)))
    for g in START_JERKS:
        j = g * kappa * kappa * v0**3
        # the slowest feed of the motion: its apex, or the start if past it
        vm = v0 - a0 * a0 / (2.0 * j) if a0 < 0.0 else v0
        if not vm > 0.0:
            break  # smaller jerks reverse the feed before the apex
        span = _start_span(b, levels, J, cap, v0, a0, j, vm)
        if span is None:
            continue
        k1, t2, exit_ = span
        ph = Phases(np.array([t2]), np.array([j]), np.array([a0]), np.array([v0]),
                    np.array([float(b.s0[0])]))
        if _within_limits(grid, int(starts[0]), int(starts[k1 + 1]), ph, limits, shares,
                          hard):
            return Valley(0, k1, ph, (v0, a0), exit_)
    return None


def _braking_reach(b: SegmentBudgets, v0: float, a0: float) -> int:
    """How many planning segments from the first one begin before the start (v0, a0)
    could come to rest under the first segment's budgets (A, J): the segments whose
    caps a start below its own first cap may still be above: a replan a hair before a
    tight bend that the last plan passed in a valley motion continues that motion
    (c-rand4-xyza's replan at s = 208.19 from 76.6 mm/s braking at 700 mm/s^2 under a
    first cap of 86.8 mm/s, with caps of 70.5 and 56.1 mm/s within 3.5 mm; with only the
    first segment's cap considered the engine wound the path in 7.93 s, 7.61 s now)."""
    A, J = float(b.A[0]), float(b.J[0])
    if not (A > 0.0 and J > 0.0):
        return 1
    # rest from (v0, a0): turn a0 to -A, brake at A, turn back (an overestimate)
    t = max(a0, 0.0) / J + v0 / A + A / J
    return max(1, int(np.searchsorted(b.s0, float(b.s0[0]) + v0 * t, side="right")))


def _start_span(b: SegmentBudgets, levels: FeedLevels, J: np.ndarray, cap: np.ndarray,
                v0: float, a0: float, j: float, vm: float
                ) -> tuple[int, float, tuple[float, float]] | None:
    """The shortest span 0 .. k1 at whose end the motion v0 + a0 t + j t^2 / 2 (slowest
    feed vm) is past its apex and within segment k1 + 1's cap and budgets (`_end_ok`):
    (k1, its duration, the exit state), or None (a corner or MAX_SPAN first)."""
    n = b.L.size
    for k1 in range(min(MAX_SPAN, n - 1)):
        if k1 > 0 and not cap[k1] > 0.0:
            return None  # the machine stops at a corner: no valley crosses it
        d = float(b.s0[k1] + b.L[k1] - b.s0[0])
        hi = d / vm
        t2 = cubic_time_at(d, v0, a0, j, hi, hi, 60, 1e-15 * hi)
        v2, a2 = v0 + a0 * t2 + j * t2 * t2 / 2.0, a0 + j * t2
        if a2 >= 0.0 and cap[k1 + 1] > 0.0 and _end_ok(
                b, levels, J, k1 + 1, v2, a2, float(cap[min(k1 + 2, cap.size - 1)])):
            return k1, t2, (v2, a2)
    return None


def _end_ok(b: SegmentBudgets, levels: FeedLevels, J: np.ndarray, nb: int, v: float,
            a: float, c: float) -> bool:
    """A valley's end state (v, a) (a forward in time) lies within segment nb's cap and
    feed-level budget, and the scans' rise goes on from it there (backward in time for
    the entry, a <= 0; forward for the exit) to nb's far junction within its cap c,
    still able to level off there (else the scan restarts at that cap, and no motion
    from the restart reaches a valley's steep end)."""
    a = abs(a)
    if not (0 <= nb < b.L.size and v <= float(b.V[nb]) and a <= levels.ceiling(nb, v)):
        return False
    if not v < levels.tops[nb][-1]:
        return a == 0.0 and v <= c
    Jn = float(J[nb])
    got = rise_levels(0.0, float(b.L[nb]), v, a, levels.tops[nb], levels.accs[nb], Jn)
    return got is not None and got[1] + got[2] * abs(got[2]) / (2.0 * Jn) <= c


def raise_valley_caps(valleys: list[Valley], b: SegmentBudgets, cap: np.ndarray
                      ) -> list[Valley]:
    """In place: each valley's exit junction cap raised to the next segment's cruise cap
    (the backward scan may then arrive there above the valley's last segment's cap); the
    valleys returned with the caps they replace (`scan.backward_scan` restores one where
    it does not take the valley)."""
    out = []
    for vy in valleys:
        j = vy.k1 + 1
        out.append(replace(vy, cap=float(cap[j])))
        if j < b.L.size:
            cap[j] = max(float(cap[j]), float(b.V[j]))
    return out
