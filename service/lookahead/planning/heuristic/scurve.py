"""Jerk-limited S-curves along the path (1 DOF in s): compatibility distances, Ruckig
segments between free states, feed changes, and cutting phases at a distance.

Units: path units (mm) and seconds. A planning segment of length L runs from a state
(w0, a0) to a state (w1, a1) under a cruise cap V, a path acceleration budget A and a path
jerk budget J.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from ruckig import ControlInterface, InputParameter, Ruckig, RuckigError, Trajectory

from lookahead.planning.heuristic.reach import cubic_time_at, surely_refused


def transition_distance(v0: np.ndarray, v1: np.ndarray, A: np.ndarray,
                        J: np.ndarray) -> np.ndarray:
    """Shortest distance for a feed change v0 -> v1 with zero end accelerations
    (DESIGN.md "Heuristic"): T = |dv|/A + A/J if |dv| >= A^2/J else 2 sqrt(|dv|/J),
    D = (v0 + v1)/2 * T."""
    dv = np.abs(np.asarray(v1, dtype=float) - v0)
    A = np.asarray(A, dtype=float)
    J = np.asarray(J, dtype=float)
    T = np.where(dv >= A * A / J, dv / A + A / J, 2.0 * np.sqrt(dv / J))
    return 0.5 * (v0 + v1) * T


def reachable_feed(v0: float, L: float, A: float, J: float) -> float:
    """The largest v1 >= v0 with transition_distance(v0, v1) <= L.

    D(v0, v1) is increasing in v1, so the paper bisects on it; its inverse has a closed
    form, which we use instead (same answer to rounding, one pass instead of ~50, and this
    runs in the planner's sequential junction loops, hence scalar math):
    - |dv| >= A^2/J: D is quadratic in dv: dv^2 + b dv + c = 0, b = 2 v0 + A^2/J,
      c = 2A (v0 A/J - L);
    - else with y = sqrt(dv): y^3 + 2 v0 y - L sqrt(J) = 0, one real root (Cardano),
      polished by Newton steps against cancellation.
    D is symmetric in (v0, v1), so the same function bounds a deceleration backwards.
    """
    L = max(L, 0.0)
    p = 2.0 * v0
    q = L * math.sqrt(J)
    root = math.sqrt(q * q / 4.0 + p**3 / 27.0)
    y = max(_cbrt(q / 2.0 + root) + _cbrt(q / 2.0 - root), 0.0)
    if p > 0.0:
        y = min(y, q / p)  # an upper bound (y^3 >= 0), exact where Cardano cancels
    for _ in range(4):  # Newton on f(y) = y^3 + p y - q, f' = 3y^2 + p > 0
        fp = 3.0 * y * y + p
        if fp <= 0.0:
            break
        y = max(y - (y**3 + p * y - q) / fp, 0.0)
    dv = y * y
    if dv >= A * A / J:
        b = 2.0 * v0 + A * A / J
        c = 2.0 * A * (v0 * A / J - L)
        dv = -2.0 * c / (b + math.sqrt(max(b * b - 4.0 * c, 0.0)))
    return v0 + max(dv, 0.0)


def _cbrt(x: float) -> float:
    return math.copysign(abs(x) ** (1.0 / 3.0), x)


@dataclass(frozen=True)
class Phases:
    """Constant-jerk phases of a motion along s, arrays of equal length (one per phase):
    duration (s), jerk, and the start acceleration, feed and position (absolute s)."""

    duration: np.ndarray
    jerk: np.ndarray
    acc: np.ndarray
    vel: np.ndarray
    pos: np.ndarray


def phases_of_lists(h: list, jk: list, ac: list, ve: list, po: list) -> Phases:
    """`Phases` of five equal-length lists (duration, jerk, acc, vel, pos), as rows of one
    array (one numpy call instead of five: the scans build thousands of short motions)."""
    arr = np.array([h, jk, ac, ve, po], dtype=float).reshape(5, len(h))
    return Phases(arr[0], arr[1], arr[2], arr[3], arr[4])


class SegmentInfeasibleError(RuntimeError):
    """Ruckig found no forward-only motion for a segment."""


class SCurveSolver:
    """One-DOF Ruckig state-to-state S-curves (community edition, no waypoints)."""

    def __init__(self) -> None:
        self._otg = Ruckig(1)
        self._inp = InputParameter(1)
        self._traj = Trajectory(1)
        self._inp.min_velocity = [0.0]  # never reverse along the path
        # `segment`'s inputs that are the same in every call (scaled to the segment)
        self._inp.current_position = [0.0]
        self._inp.target_position = [1.0]
        self._inp.max_velocity = [1.0]

    def segment(self, s0: float, L: float, v0: float, a0: float, v1: float,
                V: float, A: float, J: float, a1: float = 0.0) -> Phases:
        """Time-optimal motion over [s0, s0 + L] from (v0, a0) to (v1, a1).

        Inputs are scaled to the segment (length unit L, time unit L / V) so Ruckig sees
        numbers near 1. Raises SegmentInfeasibleError if no forward-only motion exists.
        """
        if not (L > 0 and V > 0 and A > 0 and J > 0):
            raise SegmentInfeasibleError(f"bad segment L={L} V={V} A={A} J={J}")
        if surely_refused(L, v0, a0, v1, a1, V, A, J):  # what Ruckig would refuse too
            raise SegmentInfeasibleError("the target state is out of reach")
        T = L / V
        inp = self._inp  # position 0 -> 1 under velocity 1: set in __init__
        inp.current_velocity = [v0 * T / L]
        inp.current_acceleration = [a0 * T * T / L]
        inp.target_velocity = [v1 * T / L]
        inp.target_acceleration = [a1 * T * T / L]
        inp.max_acceleration = [A * T * T / L]
        inp.max_jerk = [J * T**3 / L]
        try:
            self._otg.calculate(inp, self._traj)
        except RuckigError as exc:
            reason = str(exc).splitlines()[0] if str(exc) else "ruckig"
            raise SegmentInfeasibleError(reason) from None
        return self._phases(s0, L, T, V)

    def feed_change(self, s0: float, v0: float, a0: float, v1: float, A: float,
                    J: float) -> Phases:
        """Time-optimal feed change from (v0, a0) at s0 to (v1, 0), wherever it ends
        (Ruckig's velocity interface); used to brake a start state that is above the
        limits. Scaled so that feeds are near 1 (time unit A / J)."""
        if not (A > 0 and J > 0 and v0 >= 0 and v1 >= 0):
            raise SegmentInfeasibleError(f"bad feed change A={A} J={J} v0={v0} v1={v1}")
        T = A / J
        L = max(v0, v1, A * T) * T
        inp = InputParameter(1)
        inp.control_interface = ControlInterface.Velocity
        inp.current_position = [0.0]
        inp.current_velocity = [v0 * T / L]
        inp.current_acceleration = [a0 * T * T / L]
        inp.target_velocity = [v1 * T / L]
        inp.target_acceleration = [0.0]
        inp.max_velocity = [max(v0, v1) * T / L + 1.0]
        inp.max_acceleration = [A * T * T / L]
        inp.max_jerk = [J * T**3 / L]
        try:
            self._otg.calculate(inp, self._traj)
        except RuckigError as exc:
            raise SegmentInfeasibleError(str(exc).splitlines()[0] if str(exc) else "ruckig") \
                from None
        return self._phases(s0, L, T, max(v0, v1))

    def _phases(self, s0: float, L: float, T: float, V: float) -> Phases:
        """The last trajectory's phases (brake first), scaled back to path units.

        Scalar Python over the <= 9 phases (numpy's per-call overhead on them made this
        90 % of a Ruckig segment's cost in the planner's scans); the same float
        operations as the numpy form it replaced (kept in its test as the reference)."""
        prof = self._traj.profiles[0][0]
        # a, v, p have one entry more than t, j (the end state): drop it
        t, j, a, v, p = prof.t, prof.j, prof.a, prof.v, prof.p
        rows = [(t[i], j[i], a[i], v[i], p[i]) for i in range(7) if t[i] > 0]
        brake = prof.brake
        if brake.duration > 0:
            bt, bj, ba, bv, bp = brake.t, brake.j, brake.a, brake.v, brake.p
            rows = [(bt[i], bj[i], ba[i], bv[i], bp[i]) for i in range(2) if bt[i] > 0] + rows
        scale_v = L / T
        scale_a = L / T**2
        scale_j = L / T**3
        lowest = math.inf
        for d, jk, ak, vk, _ in rows:
            # the lowest feed of each phase: its start, or inside it where the acceleration
            # passes 0 (Ruckig's velocity interface has no floor on the feed: a brake from
            # a strong deceleration can dip below 0 within one phase)
            tau = -ak / jk if jk != 0.0 else -1.0
            dip = vk - ak * ak / (2.0 * jk) if 0.0 < tau < d else vk
            lowest = min(lowest, vk * scale_v, dip * scale_v)
        if rows and lowest < -1e-9 * V:
            raise SegmentInfeasibleError("motion would reverse")
        arr = np.array([[r[0] * T for r in rows], [r[1] * scale_j for r in rows],
                        [r[2] * scale_a for r in rows], [r[3] * scale_v for r in rows],
                        [s0 + r[4] * L for r in rows]], dtype=float).reshape(5, len(rows))
        return Phases(duration=arr[0], jerk=arr[1], acc=arr[2], vel=arr[3], pos=arr[4])


def latest_feasible(attempt, lo: float, hi: float, steps: int, tol: float = 0.0,
                    best=None) -> tuple:
    """Bisection for the largest x in [lo, hi] at which `attempt(x)` is not None (the
    feasible x forming an interval from lo): (the last success, or `best` where none
    came, and its x, lo where none came), after `steps` halvings or once the bracket
    is within `tol`."""
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        trial = attempt(mid)
        if trial is None:
            hi = mid
        else:
            lo, best = mid, trial
        if hi - lo <= tol:
            break
    return best, lo


def end_state(phases: Phases) -> tuple[float, float, float]:
    """(s, v, a) at the end of the last phase."""
    h, j, a, v, s = (float(x[-1]) for x in (phases.duration, phases.jerk, phases.acc,
                                            phases.vel, phases.pos))
    return (s + v * h + a * h * h / 2.0 + j * h**3 / 6.0, v + a * h + j * h * h / 2.0,
            a + j * h)


def cut_at(phases: Phases, s_cut: float) -> tuple[Phases, float, float] | None:
    """The phases up to where they pass s_cut, and the feed and acceleration there.

    Phases that end before s_cut are extended by a cruise at their end feed (their end
    acceleration must be ~0); None if they end at rest before s_cut. The cubic of the phase
    that contains s_cut is solved by safeguarded Newton. Scalar Python over the few phases
    (numpy's per-call overhead on 3-7 elements cost 4x more in the planner's scans)."""
    return cut_lists(*(x.tolist() for x in (phases.duration, phases.jerk, phases.acc,
                                            phases.vel, phases.pos)), s_cut)


def cut_lists(h: list, jk: list, ac: list, ve: list, po: list,
              s_cut: float) -> tuple[Phases, float, float] | None:
    """`cut_at` on phases given as lists (duration, jerk, acc, vel, pos)."""
    if not h:
        return None
    for idx in range(len(h)):
        d, j, a, v, s = h[idx], jk[idx], ac[idx], ve[idx], po[idx]
        end = s + v * d + a * d * d / 2.0 + j * d**3 / 6.0
        if end >= s_cut:
            break
    else:
        v1 = v + a * d + j * d * d / 2.0
        if not v1 > 0.0:
            return None
        return (phases_of_lists([*h, (s_cut - end) / v1], [*jk, 0.0], [*ac, 0.0],
                                [*ve, v1], [*po, end]), v1, 0.0)
    t = cubic_time_at(s_cut - s, v, a, j, d, d * 0.5, 60, 1e-14 * max(d, 1e-300))
    n = idx + 1
    out = phases_of_lists([*h[:idx], t], jk[:n], ac[:n], ve[:n], po[:n])
    return out, v + a * t + j * t * t / 2.0, a + j * t


def feed_change_phases(s0: float, v0: float, a0: float, V: float, A: float,
                       J: float) -> Phases | None:
    """`feed_change_lists` as `Phases` (None where it is None)."""
    got = feed_change_lists(s0, v0, a0, V, A, J)
    return None if got is None else phases_of_lists(*got)


def feed_change_lists(s0: float, v0: float, a0: float, V: float, A: float,
                      J: float) -> tuple[list, list, list, list, list] | None:
    """The time-optimal feed change from (v0, a0) to (V, 0) under |a| <= A, |j| <= J:
    jerk +-J up to a peak acceleration, a hold at it, jerk -+J back to 0 (what Ruckig's
    velocity interface returns for |a0| <= A). Closed form, written by hand because the
    planner's scans call it once or twice per planning segment and Ruckig's Python
    round trip costs ~5x more. None if |a0| > A (then Ruckig brakes it first) or if the
    feed would dip below 0."""
    if abs(a0) > A * (1 + 1e-12) or not (A > 0 and J > 0):
        return None
    a0 = max(-A, min(A, a0))
    sign = 1.0 if v0 + a0 * abs(a0) / (2.0 * J) <= V else -1.0
    b0, dv = sign * a0, sign * (V - v0)  # mirrored: the peak acceleration is >= 0
    peak_sq = J * dv + b0 * b0 / 2.0
    peak = math.sqrt(max(peak_sq, 0.0))
    hold = 0.0
    if peak > A:
        peak = A
        hold = (dv - (2.0 * A * A - b0 * b0) / (2.0 * J)) / A
    peak = max(peak, b0)
    durations = [(peak - b0) / J, max(hold, 0.0), peak / J]
    jerks = [sign * J, 0.0, -sign * J]
    h, jk, acc, vel, pos = [], [], [], [], []
    s, v, a = s0, v0, a0
    for d, j in zip(durations, jerks, strict=True):
        if d <= 0.0:
            continue
        h.append(d)
        jk.append(j)
        acc.append(a)
        vel.append(v)
        pos.append(s)
        # the feed would dip below 0 on the way (beyond rounding: relative to the feeds
        # and to this phase's own feed drop, so a change to V = 0 that ends exactly at 0
        # is not refused for its last bit: v0 = V = 0 left no tolerance at all)
        if a < 0.0 < a + j * d:
            drop = a * a / (2.0 * j)
            if v - drop < -1e-9 * max(abs(V), abs(v0), drop):
                return None
        s += v * d + a * d * d / 2.0 + j * d**3 / 6.0
        v += a * d + j * d * d / 2.0
        a += j * d
    return h, jk, acc, vel, pos


def split_at(phases: Phases, s_cut: float) -> tuple[Phases, Phases, float, float] | None:
    """The phases before and after where they pass s_cut (inside them), and the feed and
    acceleration there; None if they end before s_cut."""
    got = cut_at(phases, s_cut)
    if got is None:
        return None
    first, v, a = got
    idx = first.duration.size - 1
    if idx >= phases.duration.size:  # cut_at extended the motion: s_cut is beyond its end
        return None
    rest_h = float(phases.duration[idx] - first.duration[idx])
    tail = slice(idx + 1, None)
    second = Phases(np.concatenate([[rest_h], phases.duration[tail]]),
                    np.concatenate([[phases.jerk[idx]], phases.jerk[tail]]),
                    np.concatenate([[a], phases.acc[tail]]),
                    np.concatenate([[v], phases.vel[tail]]),
                    np.concatenate([[s_cut], phases.pos[tail]]))
    return first, second, v, a
