"""u(s) between grid nodes where ds/du collapses (lp.rows.rough_intervals).

The LP's midpoint rows and its analytic check (`sampled_check.analytic_ratios`) locate u
between two nodes by the cubic Hermite of the nodes' (u, du/ds). The smooth G-code fit of a
winding program's lock (X held while the mandrel turns 558 deg) ends each corner blend with
ds/du falling from 1 to ~0.001 within its last 0.05 mm: a node interval across that point
put u ~1 mm of s off, the check read the blend's x_sss (8x the jerk limit where there was
0.3x) and every repair of the 100k-line program's whole-job LP failed there.
"""

from __future__ import annotations

import numpy as np

from lookahead.config import load_config
from lookahead.geometry.fits import fit_path
from lookahead.geometry.gcode import GCODE_FIT
from lookahead.planning.lp.profile import profile_from_grid
from lookahead.planning.lp.rows import GridGeometry, s_derivatives
from lookahead.planning.sampled_check import analytic_ratios


def _lock_path():
    """1 mm moves toward X = 0 (C +0.573 deg each, B -45), the lock (C +558, B to +45 with
    X held), 1 mm moves back: the winder3 fit as `lookahead plan` makes it from G-code."""
    config = load_config("winder3")
    points = [[30.0 - k, 0.573 * k, -45.0] for k in range(31)]
    points.append([0.0, points[-1][1] + 558.0, 45.0])
    points += [[float(k), points[-1][1] + 0.573 * k, 45.0] for k in range(1, 31)]
    points = np.array(points)
    path = fit_path(points, np.asarray(config.machine.path_scale), GCODE_FIT,
                    np.full(len(points), np.nan), default_tolerance=config.planner.tolerance)
    return config.machine, path


def _collapse(path) -> float:
    """Arc length where ds/du first falls below 1 % of its value just before (the end of
    the lock's first corner blend)."""
    s = np.linspace(0.0, 100.0, 200_001)
    sigma = np.linalg.norm(path.eval_u(path.u_of_s(s), 1)[1] * path.path_scale, axis=1)
    drop = np.flatnonzero((sigma[1:] < 0.01) & (sigma[:-1] >= 0.01))
    assert drop.size >= 1
    return float(s[drop[0]])


def _nodes(s_c: float) -> np.ndarray:
    """Nodes 0.1 mm apart across the blend, the collapse 0.06 mm into an interval."""
    return s_c - 0.06 + 0.1 * np.arange(-8, 9)


def test_midpoint_geometry_holds_where_ds_du_collapses():
    _, path = _lock_path()
    s = _nodes(_collapse(path))
    geo = GridGeometry.sample(path, s)
    exact = s_derivatives(path.eval_u(path.u_of_s(0.5 * (s[:-1] + s[1:])), 3),
                          path.path_scale)[:3]
    for mine, want in zip(geo.mid, exact, strict=True):
        # the Hermite's u elsewhere: within 0.1 % (a few 1e-4 here)
        np.testing.assert_allclose(mine, want, rtol=1e-3,
                                   atol=1e-3 * float(np.max(np.abs(want))))
    assert geo.rough is not None and geo.rough[8]  # the interval holding the collapse
    assert not np.any(geo.rough[:8])  # the blend before it: the cheap u(s) holds
    # a seam's geometry keeps the marks; its joining interval is judged on its nodes
    for cut in (8, 9):
        joined = GridGeometry.join(geo.take(slice(0, cut)), GridGeometry.sample(path, s[cut:]))
        assert joined.rough is not None
        np.testing.assert_array_equal(joined.rough, geo.rough)


def test_analytic_check_reads_the_path_where_the_profile_is():
    machine, path = _lock_path()
    s = _nodes(_collapse(path))
    geo = GridGeometry.sample(path, s)
    profile = profile_from_grid(s, np.full(s.size, 20.0**2), 0.0, 0.0)  # 20 mm/s throughout
    ratios = analytic_ratios(path, profile, machine.limits, geo, 0.25 * machine.dt)
    s_t, v, a, j = profile.at(ratios.t_jerk)
    d = path.eval_s(s_t, 3)
    v, a, j = v[:, None], a[:, None], j[:, None]
    exact = np.max(np.abs(d[3] * v**3 + 3.0 * d[2] * v * a + d[1] * j)
                   / machine.limits.jmax, axis=1)
    np.testing.assert_allclose(ratios.jerk, exact, rtol=1e-3, atol=1e-3)
