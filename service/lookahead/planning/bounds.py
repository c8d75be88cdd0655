"""A lower bound on motion time: time-optimal path parametrization under the axis velocity
and acceleration limits only (no jerk limit), by TOPPRA. Any jerk-limited plan from rest to
rest along the same path takes at least about this long (up to TOPPRA's grid resolution).
With per-segment feed caps, the parametrization's feed is clipped to them afterwards: the
time-optimal feed is the pointwise largest of all admissible feeds (TOPP), so the clipped
one still lies above every feed the caps admit, and its time is still a lower bound
(looser only where a cap changes: the acceleration between caps is not charged).

toppra is in the `bench` extra, so it is imported lazily.
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedCap


def toppra_time_bound(path: Path, limits: AxisLimits, gridpoints: int = 2000,
                      s_begin: float = 0.0, s_end: float | None = None,
                      feed_cap: FeedCap | None = None) -> float:
    """Minimum time (s) from rest to rest over [s_begin, s_end] under vmax and amax per
    axis (and the path speed under `feed_cap`, path units/s: see the module docstring),
    on the path re-sampled at `gridpoints` arc lengths (toppra's spline fit of it)."""
    import toppra
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    s_end = path.length if s_end is None else s_end
    n = max(gridpoints, 4)
    s = np.linspace(s_begin, s_end, 4 * n)
    pos = path.eval_s(s, order=0)[0]
    # toppra works in single precision internally: parametrize over [0, 1], not [0, L]
    spline = toppra.SplineInterpolator((s - s_begin) / (s_end - s_begin), pos)
    vlim = np.stack([-limits.vmax, limits.vmax], axis=1)
    alim = np.stack([-limits.amax, limits.amax], axis=1)
    grid = np.linspace(0.0, spline.duration, n)
    instance = algo.TOPPRA(
        [constraint.JointVelocityConstraint(vlim), constraint.JointAccelerationConstraint(alim)],
        spline, gridpoints=grid,
    )
    _, sd, _ = instance.compute_parameterization(0.0, 0.0)
    if sd is None:
        raise RuntimeError("toppra found no parametrization")
    if feed_cap is not None:  # sd is du/dt on u = (s - s_begin) / (s_end - s_begin)
        sd = np.minimum(sd, feed_cap.at(s_begin + grid * (s_end - s_begin))
                        / (s_end - s_begin))
    # constant path acceleration between grid points: dt = 2 ds / (sd_i + sd_i+1)
    return float(np.sum(2.0 * np.diff(grid) / np.maximum(sd[:-1] + sd[1:], 1e-300)))
