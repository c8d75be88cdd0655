"""Where a C1 path (pchip, a polyline's blends) has knots: the jump of x_ss there and what
it costs the feed (the LP's caps, jerk rows and its own check).

At a C1 knot the axis acceleration x_ss v^2 + x_s a steps by |jump of x_ss| v^2, which the
checker's third difference over samples dt apart sees as a jerk of up to KNOT_FD_SHARE
times that step over dt. Arc lengths s in path units, feeds v in path units / s, the
jump in axis units / path unit^2.
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path, arc_length_derivatives
from lookahead.limits import AxisLimits
from lookahead.planning.lp.grid import MIN_STEP_FRACTION, point_steps

#: the checker's third difference over samples dt apart of a step D in the axis
#: acceleration (a C1 knot passed at feed v: D = |jump of x_ss| v^2) peaks at this times
#: D / dt, for a step midway between two samples (the weights are theta^2 / 2,
#: (1 + 2 theta - 2 theta^2) / 2, (1 - theta)^2 / 2 at a step theta of a sample step in)
KNOT_FD_SHARE = 0.75


#: the one-sided limits of x_ss at a knot are taken this far (relative to |u|, at least
#: 1) to either side of it in the path parameter u. They were taken 1e-7 x the path's
#: length to either side in s: 3.4e-4 on a fuzzed 3380-unit pchip walk, where x_ss moved
#: from 50 to 539 within 1e-5 of a knot at which the fit nearly stops (x_sss ~ 1e5): the
#: jump read 150 instead of 489, and the LP's plan crossed the knot at 1.03 jmax in the
#: checker (`bench/fuzz_paths.py --method lp`, case 7999)
KNOT_SIDE_DU = 1e-9


def knot_jumps_between(path: Path, lo: float, hi: float
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """(knots, |jump of x_ss| per knot and axis) of the C1 knots strictly inside (lo, hi),
    corners excluded; None on a C2 path or when there is none.

    Corners (tangent breaks and cusps, `Path.corners_s`) are exact stops, where the feed
    and with it the step |jump| v^2 is 0; x_ss either side of a cusp is not even finite.
    Read there, a pchip walk's cusp (every axis at an extremum) gave a jump of 5.8e7 per
    mm: a crawl cap of 1e-4 mm/s on the two nodes either side of the stop (8 of the
    plan's 15.1 s), the grid refined to h / 4096 around it, and jerk rows that pinned
    those nodes at 0, which `_unstall` tried to lift in 174 LPs (tests/test_lp_knot_rows.py's
    fuzzed case, 70 s of planning). As `PiecewisePath.xss_jumps` and the heuristic's
    knot zones, which skip corners too."""
    if path.continuity() >= 2:
        return None
    knots = path.breakpoints_s()
    knots = knots[(knots > lo) & (knots < hi) & ~np.isin(knots, path.corners_s())]
    if knots.size == 0:
        return None
    u = path.u_of_s(knots)
    # one-sided limits in u (KNOT_SIDE_DU), not a step in s relative to the path's length
    du = KNOT_SIDE_DU * np.maximum(np.abs(u), 1.0)
    scale = np.asarray(path.path_scale, dtype=float)
    left = arc_length_derivatives(path.eval_u(u - du, order=3), scale)[2]
    right = arc_length_derivatives(path.eval_u(u + du, order=3), scale)[2]
    return knots, np.abs(right - left)


def c1_knot_caps(path: Path, s: np.ndarray, limits: AxisLimits, dt: float) -> np.ndarray:
    """Feed cap at the nodes next to C1 knots: sqrt(jmax dt / |jump of x_ss|) (DESIGN.md)."""
    caps = np.full(s.size, np.inf)
    found = knot_caps(path, s[0], s[-1], limits, dt)
    if found is None:
        return caps
    knots, vcap = found
    idx = np.searchsorted(s, knots)
    for lo, v in zip(idx, vcap, strict=True):
        sl = slice(max(lo - 2, 0), min(lo + 2, s.size))
        caps[sl] = np.minimum(caps[sl], v)
    return caps


def knot_caps(path: Path, lo: float, hi: float, limits: AxisLimits, dt: float
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """(knots, feed cap per knot) of the C1 knots strictly inside (lo, hi): the feed
    sqrt(jmax dt / |jump of x_ss|) at which the jump alone reaches the jerk limit, the
    least over the axes (path units / s); None on a C2 path or when there is none."""
    found = knot_jumps_between(path, lo, hi)
    if found is None:
        return None
    knots, jump = found
    with np.errstate(divide="ignore"):
        return knots, np.min(np.sqrt(limits.jmax * dt / jump), axis=1)


#: the finest node spacing at a C1 knot, as a fraction of the nominal step h (the
#: feature and limit-curve spacing stops at `grid.MIN_STEP_FRACTION` = 1/64)
KNOT_MIN_STEP_FRACTION = 1.0 / 4096.0


def knot_steps(path: Path, limits: AxisLimits, dt: float, s_feat: np.ndarray,
               step: np.ndarray, h: float, v_top: float) -> tuple[np.ndarray, np.ndarray]:
    """The wanted spacing `step` (at arc lengths s_feat, path units) with a sample at each
    C1 knot inside, wanting there h v_k / v_top for the knot's cap v_k (`knot_caps`):
    nodes no further apart in time at the cap than h at the top feed, as
    `grid.limit_curve_steps` and `grid.break_steps` want at low feeds, down to
    KNOT_MIN_STEP_FRACTION h; `grid.refine_grid` grades it back to the spacing around.

    Why: a knot where the fit nearly stops has a cap far below the feed around it, and
    between nodes h / 64 apart (the floor elsewhere) the landing on it is a jump of the
    reconstruction's acceleration, and the cap held at the nodes beside the knot
    (`c1_knot_caps`) a crawl across whole intervals: on a fuzzed pchip walk
    (`bench/fuzz_paths.py --method lp`, case 2069) a brake from 0.83 to 0.025 units/s
    within one interval at 4.2x jmax, which no repair removed, and with the knot's jump
    read at the knot (larger) a 16656 s plan; with these steps 410 s (the heuristic:
    45 s, as `c1_knot_caps` still holds each cap on two nodes either side of its knot)."""
    found = knot_caps(path, float(s_feat[0]), float(s_feat[-1]), limits, dt)
    if found is None:
        return s_feat, step
    knots, cap = found
    deep = cap < MIN_STEP_FRACTION * v_top
    want = np.maximum(h * cap[deep] / v_top, KNOT_MIN_STEP_FRACTION * h)
    return point_steps(s_feat, step, knots[deep], want)


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
