"""Where a planned profile breaks the axis limits (planner-internal repair aid).

The planners use this to find *where* to tighten: the finite differences of PROTOCOL.md
"Limits" on positions sampled at several phases of the dt grid (a stitched profile is
sampled at an arbitrary phase), end state held. The checker
(`lookahead.checker`) stays the judge; this returns per-time ratios so that a violation
can be traced back to a place on the path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile
from lookahead.planning.lp.rows import GridGeometry, s_derivatives


def sample_times(duration: float, dt: float, hold: int = 3) -> np.ndarray:
    """t = k dt for k = 0 .. ceil(T/dt) + hold (the end state is held for `hold` samples)."""
    n = int(np.ceil(duration / dt - 1e-9)) + 1 + hold
    return np.arange(n) * dt


def sample_positions(path: Path, profile: FeedProfile, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(t, axis positions (n, naxes)) at t = k dt; s(t) clipped to the profile's span."""
    t = sample_times(profile.duration, dt)
    s = profile.at(t)[0]
    return t, path.eval_s(s, order=0)[0]


@dataclass(frozen=True)
class SampledRatios:
    """The worst |value| / limit over the axes, for velocity, acceleration and jerk, at the
    times `t_vel`, `t_acc`, `t_jerk` (s from the profile's start)."""

    vel: np.ndarray
    acc: np.ndarray
    jerk: np.ndarray
    t_vel: np.ndarray
    t_acc: np.ndarray
    t_jerk: np.ndarray

    @property
    def worst(self) -> float:
        """The largest ratio; inf if any is NaN (a value not known is not within the
        limits: Python's max() skipped a NaN array's maximum, and one NaN sample hid a
        plan's every jerk excess, 4.2x jmax, from the LP's repairs)."""
        peaks = [float(r.max(initial=0.0)) for r in (self.vel, self.acc, self.jerk)]
        return np.inf if any(np.isnan(p) for p in peaks) else max(peaks)

    def merged(self, other: SampledRatios) -> SampledRatios:
        return SampledRatios(*(np.concatenate([a, b]) for a, b in zip(
            (self.vel, self.acc, self.jerk, self.t_vel, self.t_acc, self.t_jerk),
            (other.vel, other.acc, other.jerk, other.t_vel, other.t_acc, other.t_jerk),
            strict=True)))


def difference_ratios(pos: np.ndarray, limits: AxisLimits, dt: float) -> SampledRatios:
    """Finite-difference velocity, acceleration and jerk of `pos` (sampled at k dt) over
    their limits; each difference is placed at the centre of its sample window."""
    ratios, times = [], []
    for order, lim in ((1, limits.vmax), (2, limits.amax), (3, limits.jmax)):
        d = np.diff(pos, n=order, axis=0) / dt**order
        ratios.append(np.max(np.abs(d) / lim, axis=1) if len(d) else np.zeros(0))
        times.append((np.arange(len(d)) + 0.5 * order) * dt)
    return SampledRatios(*ratios, *times)


def profile_ratios(path: Path, profile: FeedProfile, limits: AxisLimits, dt: float,
                   phases: int = 4) -> SampledRatios:
    """What the planners verify: the finite differences at spacing dt of positions sampled
    every dt / phases, i.e. the checker's test at `phases` sampling phases at once (a
    stitched profile is sampled at an arbitrary phase)."""
    step = dt / phases
    t = np.arange(int(np.ceil(profile.duration / step - 1e-9)) + 1 + 3 * phases) * step
    pos = path.eval_s(profile.at(t)[0], order=0)[0]
    ratios, times = [], []
    for order, lim in ((1, limits.vmax), (2, limits.amax), (3, limits.jmax)):
        d = pos
        for _ in range(order):
            d = d[phases:] - d[:-phases]
        d = d / dt**order
        ratios.append(np.max(np.abs(d) / lim, axis=1) if len(d) else np.zeros(0))
        times.append(np.arange(len(d)) * step + 0.5 * order * dt)
    return SampledRatios(*ratios, *times)


#: `analytic_ratios` evaluates this many samples at a time: its temporaries (~40 floats
#: per sample) took 20 GB at once, and the process was killed, for a fuzzed pchip walk's
#: whole-job plan of 16656 s that crawled across grid intervals at a knot cap
#: (`bench/fuzz_paths.py --method lp`, case 2069, before `lp.knots.knot_steps`); in
#: chunks, ~0.3 GB at most (estimated from the same count)
CHECK_CHUNK = 1_000_000
#: a sample whose ds/du is below this fraction of the grid's median is at a corner where
#: the fit stops (a pchip knot with x_u = 0 in every axis): x_sss there is the difference
#: of terms ~ 1/sigma^3 .. 1/sigma^5, whose rounding grows like eps (median / sigma)^2
#: relative (2e-4 at this ratio), and its value is judged by the samples around
#: (`fill_undefined`). Measured: a fuzzed pchip walk's plan at rest 15 us after such a
#: corner read sigma 5e-14, x_sss 2.5e52 (1e12 x its true size), 2e18 x jmax, and
#: failed every repair (`bench/fuzz_paths.py`, case 377)
SINGULAR_SIGMA = 1e-6


def fill_undefined(ratio: np.ndarray) -> None:
    """In place: each NaN ratio (a sample where ds/du = 0 or nearly, `SINGULAR_SIGMA`: a
    corner at which a pchip fit stops in every axis, so that the s-derivatives are 0/0
    or rounding) becomes the larger of its neighbours' (0 if they are NaN too).

    Why the neighbours: the plan passes such a corner at rest, and x_ss grows like
    |s - corner|^(-1/2) beside it, so no one-sided value exists; the checker's
    differences average the motion over the samples around, which are judged."""
    bad = np.isnan(ratio)
    if not np.any(bad):
        return
    padded = np.concatenate([[np.nan], ratio, [np.nan]])
    near = np.fmax(padded[:-2], padded[2:])
    ratio[bad] = np.nan_to_num(near[bad], nan=0.0)


def analytic_ratios(path: Path, profile: FeedProfile, limits: AxisLimits,
                    geo: GridGeometry, step: float) -> SampledRatios:
    """The continuous axis velocity, acceleration and jerk over their limits at t = k step
    (s from the profile's start), from the profile's exact polynomial derivatives and the
    path's s-derivatives (chain rule: x_s v, x_ss v^2 + x_s a, x_sss v^3 + 3 x_ss v a +
    x_s j).

    The checker's finite differences are averages of these continuous values over one to
    three samples, so bounding them bounds the checker's. u(s) between the grid nodes is
    a cubic Hermite interpolant of the nodes' (u, du/ds = 1/sigma): it only locates where
    the derivatives are evaluated (error in s ~1e-6 of a node spacing, at most 0.3 % on the
    fast corpus's unmarked intervals), so it does not need the
    exact arc-length inversion that dominates `profile_ratios`; except on the intervals
    `geo.rough` marks (ds/du changes too much there for a cubic, `rows.rough_intervals`),
    whose samples get the exact inversion. Evaluated CHECK_CHUNK samples at a time.
    """
    if geo.u is None or geo.sigma is None:
        raise ValueError("analytic_ratios needs a GridGeometry sampled with u and sigma")
    t = np.arange(int(np.ceil(profile.duration / step)) + 1) * step
    u_of_s = CubicHermiteSpline(geo.s, geo.u, 1.0 / geo.sigma, extrapolate=True)
    sigma_floor = SINGULAR_SIGMA * np.median(geo.sigma)
    vel, acc, jerk = np.empty(t.size), np.empty(t.size), np.empty(t.size)
    for lo in range(0, t.size, CHECK_CHUNK):
        part = slice(lo, lo + CHECK_CHUNK)
        s, v, a, j = profile.at(t[part])
        u = u_of_s(s)
        if geo.rough is not None and np.any(geo.rough):
            interval = np.clip(np.searchsorted(geo.s, s, side="right") - 1, 0,
                               geo.rough.size - 1)
            exact = geo.rough[interval]
            if np.any(exact):
                u[exact] = path.u_of_s(s[exact])
        d1, d2, d3, sigma = s_derivatives(path.eval_u(u, order=3), path.path_scale)
        v, a, j = v[:, None], a[:, None], j[:, None]
        vel[part] = np.max(np.abs(d1 * v) / limits.vmax, axis=1)
        acc[part] = np.max(np.abs(d2 * v * v + d1 * a) / limits.amax, axis=1)
        jerk[part] = np.max(np.abs(d3 * v**3 + 3.0 * d2 * v * a + d1 * j) / limits.jmax,
                            axis=1)
        singular = ~(sigma >= sigma_floor)
        for out in (vel, acc, jerk):
            out[part][singular] = np.nan
    for out in (vel, acc, jerk):
        fill_undefined(out)
    return SampledRatios(vel, acc, jerk, t, t, t)
