"""Where a C1 path (pchip, a polyline's blends) has knots: the jump of x_ss there and what
it costs the feed (the LP's caps, jerk rows and its own check).

At a C1 knot the axis acceleration x_ss v^2 + x_s a steps by |jump of x_ss| v^2, which the
checker's third difference over samples dt apart sees as a jerk of up to KNOT_FD_SHARE
times that step over dt. Arc lengths s in path units, feeds v in path units / s, the
jump in axis units / path unit^2.
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits

#: the checker's third difference over samples dt apart of a step D in the axis
#: acceleration (a C1 knot passed at feed v: D = |jump of x_ss| v^2) peaks at this times
#: D / dt, for a step midway between two samples (the weights are theta^2 / 2,
#: (1 + 2 theta - 2 theta^2) / 2, (1 - theta)^2 / 2 at a step theta of a sample step in)
KNOT_FD_SHARE = 0.75


def knot_jumps_between(path: Path, lo: float, hi: float
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """(knots, |jump of x_ss| per knot and axis) of the C1 knots strictly inside (lo, hi);
    None on a C2 path or when there is none."""
    if path.continuity() >= 2:
        return None
    knots = path.breakpoints_s()
    knots = knots[(knots > lo) & (knots < hi)]
    if knots.size == 0:
        return None
    eps = 1e-7 * max(path.length, 1.0)
    jump = np.abs(path.eval_s(knots + eps, 2)[2] - path.eval_s(knots - eps, 2)[2])
    return knots, jump


def c1_knot_caps(path: Path, s: np.ndarray, limits: AxisLimits, dt: float) -> np.ndarray:
    """Feed cap at the nodes next to C1 knots: sqrt(jmax dt / |jump of x_ss|) (DESIGN.md)."""
    caps = np.full(s.size, np.inf)
    found = knot_jumps_between(path, s[0], s[-1])
    if found is None:
        return caps
    knots, jump = found
    with np.errstate(divide="ignore"):
        vcap = np.min(np.sqrt(limits.jmax * dt / jump), axis=1)
    idx = np.searchsorted(s, knots)
    for lo, v in zip(idx, vcap, strict=True):
        sl = slice(max(lo - 2, 0), min(lo + 2, s.size))
        caps[sl] = np.minimum(caps[sl], v)
    return caps


def knot_jumps(path: Path, s: np.ndarray) -> np.ndarray | None:
    """Per node (n, naxes): the largest |jump of x_ss| (axis units / path unit^2) of the
    C1 knots within its neighbouring intervals (s_i-1, s_i+1), times KNOT_FD_SHARE;
    None on a C2 path or where no knot lies inside."""
    found = knot_jumps_between(path, s[0], s[-1])
    if found is None:
        return None
    knots, jump = found
    interval = np.clip(np.searchsorted(s, knots) - 1, 0, s.size - 2)
    per_interval = np.zeros((s.size - 1, jump.shape[1]))
    np.maximum.at(per_interval, interval, jump)
    out = np.zeros((s.size, jump.shape[1]))
    out[:-1] = per_interval
    out[1:] = np.maximum(out[1:], per_interval)
    return KNOT_FD_SHARE * out if np.any(out > 0.0) else None


def knot_fd_ratio(path: Path, limits: AxisLimits, dt: float, s: np.ndarray,
                  v: np.ndarray) -> np.ndarray | None:
    """The checker's extra jerk at C1 knots over the jerk limit, at arc lengths s with
    feed v (the analytic check sees only the smooth jerk between the knots): max over the
    axes of KNOT_FD_SHARE |jump of x_ss| v^2 / (dt jmax) where a knot lies within two
    samples (2 v dt) of s, else 0; None on a C2 path."""
    if s.size == 0:
        return None
    found = knot_jumps_between(path, s.min() - 1e-9, s.max() + 1e-9)
    if found is None:
        return None
    knots, jump = found
    per_knot = np.max(jump / limits.jmax, axis=1)
    i = np.clip(np.searchsorted(knots, s), 1, knots.size - 1) if knots.size > 1 else \
        np.zeros(s.size, dtype=int)
    lo = np.maximum(i - 1, 0)
    near_lo = np.abs(s - knots[lo]) <= 2.0 * v * dt
    near_hi = np.abs(s - knots[i]) <= 2.0 * v * dt
    worst = np.maximum(np.where(near_lo, per_knot[lo], 0.0), np.where(near_hi, per_knot[i], 0.0))
    return KNOT_FD_SHARE * worst * v**2 / dt
