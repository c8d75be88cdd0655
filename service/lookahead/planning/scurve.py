"""Jerk-limited S-curves along the path: compatibility distances and Ruckig segments.

Units: path units (mm) and seconds. A planning segment of length L runs from feed w0 to
feed w1, path acceleration 0 at both ends, under a cruise cap V, a path acceleration budget
A and a path jerk budget J.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from ruckig import ControlInterface, InputParameter, Ruckig, RuckigError, Trajectory


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


class SegmentInfeasibleError(RuntimeError):
    """Ruckig found no forward-only motion for a segment."""


class SCurveSolver:
    """One-DOF Ruckig state-to-state S-curves (community edition, no waypoints)."""

    def __init__(self) -> None:
        self._otg = Ruckig(1)
        self._inp = InputParameter(1)
        self._traj = Trajectory(1)
        self._inp.min_velocity = [0.0]  # never reverse along the path

    def segment(self, s0: float, L: float, v0: float, a0: float, v1: float,
                V: float, A: float, J: float) -> Phases:
        """Time-optimal motion over [s0, s0 + L] from (v0, a0) to (v1, 0).

        Inputs are scaled to the segment (length unit L, time unit L / V) so Ruckig sees
        numbers near 1. Raises SegmentInfeasibleError if no forward-only motion exists.
        """
        if not (L > 0 and V > 0 and A > 0 and J > 0):
            raise SegmentInfeasibleError(f"bad segment L={L} V={V} A={A} J={J}")
        T = L / V
        inp = self._inp
        inp.current_position = [0.0]
        inp.current_velocity = [v0 * T / L]
        inp.current_acceleration = [a0 * T * T / L]
        inp.target_position = [1.0]
        inp.target_velocity = [v1 * T / L]
        inp.target_acceleration = [0.0]
        inp.max_velocity = [1.0]
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
        """The last trajectory's phases (brake first), scaled back to path units."""
        prof = self._traj.profiles[0][0]
        rows = []
        brake = prof.brake
        if brake.duration > 0:
            rows += zip(brake.t, brake.j, brake.a, brake.v, brake.p, strict=False)
        rows += zip(prof.t, prof.j, prof.a, prof.v, prof.p, strict=False)  # a, v, p have 8
        arr = np.array(rows)
        arr = arr[arr[:, 0] > 0]
        vel = arr[:, 3] * (L / T)
        if np.any(vel < -1e-9 * V):
            raise SegmentInfeasibleError("motion would reverse")
        return Phases(
            duration=arr[:, 0] * T,
            jerk=arr[:, 1] * (L / T**3),
            acc=arr[:, 2] * (L / T**2),
            vel=vel,
            pos=s0 + arr[:, 4] * L,
        )
