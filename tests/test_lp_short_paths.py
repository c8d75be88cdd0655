"""The LP on short paths (rest to rest, a few grid steps long): 50-point fits of 35-100 mm
and B-spline pieces used to end in "the jerk LP has no solution" (a stalled node next to a
rest end) or in failed repairs on a grid too coarse for the start and stop S-curves. Each
plan must now exist, reach the path's end and pass the finite-difference checker."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry.nurbs import BSplinePath, CompositePath
from lookahead.geometry.spline_path import fit_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner, default_grid_step
from lookahead.sampling import sample_plan

MACHINE = default_config().machine
SCALE = np.asarray(MACHINE.path_scale)
LIMITS = MACHINE.limits.scaled(0.98)
DT = MACHINE.dt
K3 = np.array([0, 0, 0, 0, 1, 1, 1, 1.0])


def arch_fit(length: float, height: float):
    t = np.linspace(0.0, 1.0, 50)
    return fit_points(np.column_stack([length * t, height * np.sin(np.pi * t)]), SCALE)


def piece(ctrl, weights=None):
    return BSplinePath(3, K3, np.asarray(ctrl, dtype=float), SCALE, weights)


PIECES = [
    piece([[0, 0], [10, 5], [20, 5], [30, 0]]),
    piece([[30, 0], [40, -5], [50, -5], [60, 0]]),
    piece([[60, 0], [60, 20], [50, 40], [40, 40]], np.array([1, 0.7, 1.3, 1.0])),
    piece([[40, 40], [20, 40], [0, 20], [0, 0]]),
]

CASES = {
    "fit-30mm-arch": lambda: arch_fit(30.0, 5.0),
    "fit-60mm-arch": lambda: arch_fit(60.0, 5.0),
    "fit-45mm-line": lambda: arch_fit(45.0, 0.0),
    "fit-100mm-flat-arch": lambda: arch_fit(100.0, 2.0),
    "bspline-one-piece": lambda: PIECES[0],
    "bspline-two-pieces": lambda: CompositePath(PIECES[:2]),
    "bspline-four-pieces": lambda: CompositePath(PIECES),
}


@pytest.mark.parametrize("name", list(CASES))
def test_short_path_plans_to_its_end_within_the_limits(name):
    path = CASES[name]()
    # short: at most ~40 default grid steps (the composites stop at their corners, so
    # each of their spans is a few steps), where the failures were
    assert path.length < 40 * default_grid_step(path, LIMITS)
    res = LPPlanner().plan(PlanRequest(path, LIMITS, PathState(0.0), path.length, dt=DT))
    prof = res.profile
    assert float(prof.s_of_t(prof.s_of_t.x[-1])) == pytest.approx(path.length, abs=1e-9)
    t = np.linspace(0.0, prof.duration, 400)
    s, v, _, _ = prof.at(t)
    assert np.all(np.diff(s) >= -1e-12) and np.all(v >= -1e-9)
    assert np.isfinite(prof.duration) and prof.duration < 10.0
    rep = check_positions(sample_plan(path, prof, DT).pos, LIMITS, DT)
    assert rep.violations == 0, rep.first


def test_stalled_node_next_to_rest_is_lifted():
    """The 35 mm arch's jerk pass put q = 0 next to the start (an interval that never
    ends); the re-solve lifts it: every interval of the grid solution has a finite time."""
    path = arch_fit(30.0, 5.0)
    res = LPPlanner().plan(PlanRequest(path, LIMITS, PathState(0.0), path.length, dt=DT))
    q = np.asarray(res.info["grid_q"])
    assert q[0] == 0.0 and q[-1] == 0.0
    assert np.all(q[1:-1] > 0.0)
