"""The LP grid sees bends shorter than its feature-sample spacing (lp.grid.feature_samples).

A G-code corner blend of the smooth fit on the winder3 machine is 0.64 mm long (radius
0.15 mm) while the grid judges the path's bends on samples h / 4 = 1.5 mm apart: a blend
between two samples got no extra nodes, and every repair of the whole-job LP on a
100k-line winding program failed there (jerk 500x its limit, "stuck there").
"""

from __future__ import annotations

import numpy as np

from lookahead.checker import check_positions
from lookahead.config import load_config
from lookahead.geometry.fits import fit_path
from lookahead.geometry.gcode import GCODE_FIT
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner, default_grid_step
from lookahead.planning.lp.grid import HIDDEN_SAMPLES, feature_samples
from lookahead.planning.lp.planner import FEATURE_SAMPLES
from lookahead.sampling import sample_plan


def _blend_path():
    """1 mm moves along X with the mandrel turning, the first of which also turns the
    delivery head by 45 deg: the smooth fit blends the corner after it within 0.6 mm."""
    machine = load_config("winder3").machine
    points = [[0.0, 52758.0, 0.0]]
    points += [[float(k), 52758.0 + 0.573 * k, 45.0] for k in range(1, 30)]
    path = fit_path(np.array(points), np.asarray(machine.path_scale), GCODE_FIT,
                    np.full(len(points), 0.05), default_tolerance=0.05)
    return machine, path


def _bend(path) -> tuple[float, float, float]:
    """(centre, first, last) arc length of the sharpest bend (curvature > 1 / path unit)."""
    s = np.linspace(0.0, path.length, 400_001)
    k = np.linalg.norm(path.eval_s(s, 2)[2] * path.path_scale, axis=1)
    inside = s[k > 1.0]
    return float(s[np.argmax(k)]), float(inside[0]), float(inside[-1])


def test_feature_samples_are_finer_only_where_a_bend_hides():
    machine, path = _blend_path()
    centre, first, last = _bend(path)
    spacing = default_grid_step(path, machine.limits) / FEATURE_SAMPLES
    lo = centre - 3.5 * spacing  # the bend halfway between two uniform samples
    s, d = feature_samples(path, lo, lo + 12.0 * spacing, spacing)
    assert np.all(np.diff(s) > 0.0)
    assert np.allclose(d, path.eval_s(s, 3))
    assert np.count_nonzero((s > first) & (s < last)) >= 3
    extra = s.size - 13
    assert extra == HIDDEN_SAMPLES - 1  # one interval sampled finer, no other
    # a rest node in that interval: graded by the grid already, nothing added
    s_rest, _ = feature_samples(path, lo, lo + 12.0 * spacing, spacing, np.array([centre]))
    assert s_rest.size == 13
    # a circle's bends are all resolved: nothing added
    circle_pts = np.stack([np.zeros(200), np.linspace(0.0, 720.0, 200), np.zeros(200)], 1)
    circle_pts[:, 0] = 20.0 * np.cos(np.radians(circle_pts[:, 1]))
    circle = fit_path(circle_pts, np.asarray(machine.path_scale), GCODE_FIT,
                      np.full(200, 0.05), default_tolerance=0.05)
    s_c, _ = feature_samples(circle, 0.0, circle.length, spacing)
    assert s_c.size == int(np.ceil(circle.length / spacing)) + 1


def test_refine_adds_nodes_in_a_bend_between_feature_samples():
    machine, path = _blend_path()
    centre, first, last = _bend(path)
    assert last - first < 1.0  # the blend is short
    planner = LPPlanner()
    h = default_grid_step(path, machine.limits)
    spacing = h / FEATURE_SAMPLES
    assert last - first < 0.5 * spacing  # it fits between two uniform samples
    # a window whose uniform feature samples fall half a spacing either side of the bend
    lo = centre - 3.5 * spacing
    nodes = np.linspace(lo, lo + 12.0 * spacing, 4)
    refined, _ = planner.refine(path, nodes, np.empty(0, dtype=int), h)
    in_bend = refined[(refined > first) & (refined < last)]
    assert in_bend.size >= 2, (in_bend, first, last)


def test_whole_job_lp_plans_a_short_blend_within_the_limits():
    machine, path = _blend_path()
    request = PlanRequest(path, machine.limits, PathState(0.0), path.length, dt=machine.dt)
    result = LPPlanner().plan(request)
    samples = sample_plan(path, result.profile, machine.dt)
    report = check_positions(samples.pos, machine.limits, machine.dt)
    assert report.violations == 0
    assert np.allclose(samples.pos[-1], path.eval_s(np.array([path.length]), 0)[0, 0])
