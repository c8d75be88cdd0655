"""Jerk-limited start/stop envelopes for the feed LP.

The LP's jerk rows vanish where q = 0 (jerk = sqrt(q) L), so from rest it would step the
path acceleration from 0 to its maximum. The cure is an upper bound on q near every point
where the state is prescribed: the fastest feed a 1-DOF S-curve (path jerk <= J, path
acceleration <= A) can reach at distance d from that state. Time-reversed, the same bound
holds before a stop.
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits


def path_limits(path: Path, limits: AxisLimits) -> tuple[float, float]:
    """Conservative path acceleration and jerk (path units / s^2, / s^3) at low feed:
    the axis acceleration and jerk there are x'_k a and x'_k j, and |x'_k| <= 1/path_scale_k."""
    xmax = 1.0 / np.asarray(path.path_scale, dtype=float)
    return float(np.min(limits.amax / xmax)), float(np.min(limits.jmax / xmax))


def braking_distance(v: float, a_max: float, j_max: float) -> float:
    """Distance to stop from feed v at zero acceleration with a jerk-limited S-curve
    (path units): v/2 (v/A + A/J) if v >= A^2/J, else v sqrt(v/J)."""
    if v >= a_max**2 / j_max:
        return 0.5 * v * (v / a_max + a_max / j_max)
    return v * float(np.sqrt(v / j_max))


def reachable_q(d: np.ndarray, v0: float, a0: float, J: np.ndarray | float,
                A: float) -> np.ndarray:
    """The largest q = v^2 reachable at distance d >= 0 from state (v0, a0) with jerk <= J
    and acceleration <= A: jerk J until the acceleration is A, then acceleration A.

    Hand-written (a closed-form S-curve phase plus a vectorized bisection for t(d) in
    the jerk phase): one cubic per node, no library call fits better.
    """
    d = np.asarray(d, dtype=float)
    J = np.broadcast_to(np.asarray(J, dtype=float), d.shape)
    a0 = min(a0, A)
    t1 = (A - a0) / J

    def dist(t):
        return v0 * t + 0.5 * a0 * t**2 + J * t**3 / 6.0

    def speed(t):
        return np.maximum(v0 + a0 * t + 0.5 * J * t**2, 0.0)

    s1 = dist(t1)
    in_jerk = d <= s1
    lo, hi = np.zeros_like(d), t1.copy()
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = dist(mid) < d
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    q_jerk = speed(0.5 * (lo + hi)) ** 2
    q_acc = speed(t1) ** 2 + 2.0 * A * np.maximum(d - s1, 0.0)
    return np.where(in_jerk, q_jerk, q_acc)
