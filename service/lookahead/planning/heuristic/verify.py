"""The heuristic's own verification: axis velocity, acceleration and jerk at every grid point
(budget and check points of each cell) from the planned profile's exact path state and the
path's s-derivatives (chain rule), against the full limits; per planning segment.

Frames and units as in `path_limits`; the finite-difference checker stays the judge of the
sampled stream, this finds the segments to repair.
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile
from lookahead.planning.heuristic.path_limits import PathGrid
from lookahead.planning.heuristic.profile_build import state_at_s
from lookahead.planning.sampled_check import profile_ratios

#: largest feed at a corner, as a fraction of the smallest axis vmax (plans stop there: a
#: rise from rest starts at feed 0 exactly; 1e-6 leaves room for rounding only)
CORNER_FEED = 1e-6


def failing_cells(profile: FeedProfile, grid: PathGrid, lim: AxisLimits) -> np.ndarray:
    """(ncell,) True where some axis exceeds `lim` at one of the cell's points."""
    ncell, npts, naxes = grid.xs.shape
    v, a, j = (x[:, None] for x in state_at_s(profile, grid.s.ravel()))
    # flat (points, axes) views: one pass per term, no broadcasting over cell axes
    xs, xss, xsss = (x.reshape(-1, naxes) for x in (grid.xs, grid.xss, grid.xsss))
    jmax = (lim.jmax if np.all(grid.jerk_scale == 1.0)
            else np.repeat(grid.jerk_scale, npts)[:, None] * lim.jmax)
    bad = np.abs(xs * v) > lim.vmax
    bad |= np.abs(xss * (v * v) + xs * a) > lim.amax
    bad |= np.abs(xsss * (v * v * v) + xss * (3.0 * v * a) + xs * j) > jmax
    out = bad.reshape(ncell, -1).any(axis=1)
    corners = np.nonzero(grid.corner_after)[0]
    if corners.size:
        # the machine stops at a corner (the grid's points stay a quarter cell away from
        # it, so the terms above do not see a feed kept through one)
        v_corner = state_at_s(profile, grid.edges[corners + 1])[0]
        out[corners] |= np.abs(v_corner) > CORNER_FEED * float(np.min(lim.vmax))
    return out


def failing_segments(profile: FeedProfile, grid: PathGrid, starts: np.ndarray,
                     lim: AxisLimits) -> np.ndarray:
    """(nseg,) True where some cell of the segment fails (`failing_cells`)."""
    return np.logical_or.reduceat(failing_cells(profile, grid, lim), starts[:-1])


def sampled_failing_segments(path: Path, profile: FeedProfile, grid: PathGrid,
                             starts: np.ndarray, lim: AxisLimits, dt: float) -> np.ndarray:
    """(nseg,) True where the finite differences of PROTOCOL.md "Limits" on positions
    sampled every dt / 4 (the checker's test at four sampling phases at once) exceed `lim`
    somewhere in the segment. Catches what the grid points miss (a term peaking between
    them, an acceleration jump averaged over one sample)."""
    ratios = profile_ratios(path, profile, lim, dt)
    tol = 1.0 + 1e-9
    times = [t[r > tol] for r, t in ((ratios.vel, ratios.t_vel), (ratios.acc, ratios.t_acc),
                                     (ratios.jerk, ratios.t_jerk))]
    t_bad = np.concatenate(times)
    nseg = starts.size - 1
    if not t_bad.size:
        return np.zeros(nseg, dtype=bool)
    # a difference spans up to 3 samples: mark the segments at both ends of the window
    t_all = np.concatenate([t_bad - 1.5 * dt, t_bad + 1.5 * dt])
    s_bad = profile.at(np.clip(t_all, 0.0, profile.duration))[0]
    seg_edges = grid.edges[starts]
    seg = np.clip(np.searchsorted(seg_edges, s_bad, side="right") - 1, 0, nseg - 1)
    out = np.zeros(nseg, dtype=bool)
    out[seg] = True
    return out
