"""A braking start released in closed form, where the grid is too coarse to follow it.

A replan from the braking into a plan's end (feed v0 of a few path units / s, path
acceleration a0 < 0 of hundreds) must first bring the acceleration to 0: with a path jerk
j that costs the feed a0^2 / (2 j) and takes -a0 / j seconds, over a distance of order
v0^2 / |a0| (0.02-0.1 mm on the fast corpus), while the LP's first grid interval is a few
mm. Its quintic, with the start state at one end and a node mm away at the other, cannot
dip and rise again inside one interval: it reversed (ds/dt down to -0.67 mm/s), which the
sampler holds (s non-decreasing) and the checker sees as a jerk of 1.1-40 x the limit
(issue 13: every LP replan refused on the fast corpus's replan-continuity bench was this).

The release: constant path jerk j from (s0, v0, a0) until the acceleration is 0, then the
LP from (s1, v1, 0). Its axis jerk x''' v^3 + 3 x'' v a + x' j is bounded by construction
(v <= v0 and a0 <= a <= 0 along it), so j is the largest that keeps it within the limits,
and it is used only where it ends within one grid step (where the LP could follow it, it
stays the LP's). Arc lengths in path units, times in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import PPoly

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile, PathState
from lookahead.planning.lp.knots import knot_fd_ratio
from lookahead.planning.lp.rows import GridGeometry
from lookahead.planning.lp.seam import REST
from lookahead.planning.sampled_check import analytic_ratios

#: points on the release's longest possible span at which the geometry bounds its jerk
GEOMETRY_SAMPLES = 9
#: the release's axis jerk bound as a fraction of the limits: it is exact (no quintic
#: overshoot to absorb), the margin is for rounding and for the geometry between the
#: samples (at 1.0 the check measured 1 + 2e-16). A smaller one keeps less feed,
#: v1 = v0 - a0^2 / (2 j): at 0.99, 0.01 of a0^2 / (2 j) (< 0.05 mm/s on the fast corpus)
RELEASE_MARGIN = 0.99


@dataclass(frozen=True)
class Release:
    """The closed-form release: path jerk `jerk` for `profile.duration` seconds, from the
    request's start to `end` (path acceleration 0)."""

    jerk: float
    end: PathState
    profile: FeedProfile


def release_jerk(geo: GridGeometry, jmax: np.ndarray, v0: float, a0: float) -> float:
    """The largest path jerk j (path units / s^3) whose release from (v0, a0 < 0) keeps
    |x'''_k v^3 + 3 x''_k v a + x'_k j| <= jmax_k at the nodes of `geo` (the span of the
    release), with v <= v0 and |a| <= |a0| along it; <= 0 if none."""
    rest = np.abs(geo.d3) * v0**3 + 3.0 * np.abs(geo.d2) * v0 * abs(a0)
    with np.errstate(divide="ignore"):
        per = (jmax[None, :] - rest) / np.abs(geo.d1)
    return float(np.min(per))


def start_release(path: Path, limits: AxisLimits, start: PathState, h: float,
                  s_max: float, dt: float, stops: np.ndarray | None = None
                  ) -> Release | None:
    """The release of a braking start (a0 < 0, v0 > REST) at the largest path jerk within
    RELEASE_MARGIN x the axis jerk limits (it is exact: nothing to absorb), if it ends within
    the grid step h (path units), before s_max and before any rest point in `stops`, and
    its analytic check (every dt/2, with the C1-knot term) passes the limits; else None
    (the LP plans the start itself).

    j must exceed a0^2 / (2 v0), the least jerk that does not reverse; the release then
    lies within (2/3) v0^2 / |a0| of the start, where the geometry is sampled."""
    v0, a0 = float(start.v), float(start.a)
    if not (v0 > REST and a0 < 0.0):
        return None  # (a feed <= REST is rest: the LP's start from rest)
    j_min = a0 * a0 / (2.0 * v0)
    span = min(2.0 / 3.0 * v0 * v0 / -a0, h)
    if not span > 0.0:
        return None
    geo = GridGeometry.sample(path, start.s + np.linspace(0.0, span, GEOMETRY_SAMPLES),
                              midpoints=False)
    j = release_jerk(geo, RELEASE_MARGIN * limits.jmax, v0, a0)
    if not j > j_min:
        return None
    T = -a0 / j
    dist = v0 * T + 0.5 * a0 * T * T + j * T**3 / 6.0
    s1 = start.s + dist
    if not (dist < h and start.s < s1 < s_max) or (stops is not None and np.any(
            (stops > start.s) & (stops <= s1))):
        return None
    pp = PPoly(np.array([[j / 6.0], [0.5 * a0], [v0], [start.s]]), np.array([0.0, T]),
               extrapolate=False)
    profile = FeedProfile(pp)
    v1 = max(v0 + a0 * T + 0.5 * j * T * T, 0.0)
    if not _within_limits(path, limits, profile, dt):
        return None
    return Release(j, replace(start, s=s1, v=v1, a=0.0), profile)


def _within_limits(path: Path, limits: AxisLimits, profile: FeedProfile, dt: float) -> bool:
    """The release's continuous axis velocity, acceleration and jerk (and the checker's
    extra jerk at C1 knots) every dt / 2 are within the limits."""
    s_end = float(profile.at(np.array([profile.duration]))[0, 0])
    s0 = float(profile.at(np.zeros(1))[0, 0])
    geo = GridGeometry.sample(path, np.array([s0, s_end]), midpoints=False)
    ratios = analytic_ratios(path, profile, limits, geo, 0.5 * dt)
    jerk = ratios.jerk
    s_t, v_t = profile.at(ratios.t_jerk)[:2]
    extra = knot_fd_ratio(path, limits, dt, s_t, v_t)
    if extra is not None:
        jerk = jerk + extra
    worst = max(float(np.max(ratios.vel)), float(np.max(ratios.acc)), float(np.max(jerk)))
    return worst <= 1.0
