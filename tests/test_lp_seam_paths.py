"""LP seams across path objects: the streaming fit hands out a new Path whenever points
arrive, with its final part unchanged. A replan on the grown path must still continue the
last plan (no cold plan), and a path that differs where nodes are reused must not."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry import StreamingFit, fit_points, preset_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner

WINDOW = 1400.0  # path units


@pytest.fixture(scope="module")
def grown():
    """The first plan on a stream of 1200 points, and the path after 400 more arrived."""
    machine = default_config().machine
    scale = np.asarray(machine.path_scale)
    _, pts, _ = preset_points("tube-1450")
    fit = StreamingFit(2, scale, "cubic")
    fit.extend(pts[:1200])
    first_path = fit.path()
    first_final = fit.final_length
    fit.extend(pts[1200:1600])
    limits, dt = machine.limits.scaled(0.98), machine.dt
    planner = LPPlanner()
    s_end = min(first_final, WINDOW)
    first = planner.plan(PlanRequest(first_path, limits, PathState(0.0), s_end, dt=dt))
    return planner, first_path, fit.path(), fit.final_length, first, limits, dt, pts


def state_at(profile, t: float) -> PathState:
    s, v, a, _ = profile.at(np.array([t]))[:, 0]
    return PathState(float(s), max(float(v), 0.0), float(a))


def test_a_grown_path_continues_the_last_plan_within_the_limits(grown):
    planner, old_path, new_path, final, first, limits, dt, _ = grown
    assert new_path is not old_path
    k = 300
    start = state_at(first.profile, k * dt)
    s_end = min(final, start.s + WINDOW)
    req = PlanRequest(new_path, limits, start, s_end, dt=dt)
    assert planner.find_seam(req) is not None
    res = planner.plan(req)
    assert res.info["seam"] is not None
    s0, v0, a0, _ = res.profile.at(np.array([0.0]))[:, 0]
    assert (s0, v0, a0) == pytest.approx((start.s, start.v, start.a), rel=1e-9, abs=1e-7)
    # played: the first plan up to sample k, then the replan to rest, on the new path
    s_first = first.profile.at(np.arange(k) * dt)[0]
    s_next = res.profile.at(np.arange(int(np.ceil(res.profile.duration / dt)) + 4) * dt)[0]
    pos = new_path.eval_s(np.concatenate([s_first, s_next]), 0)[0]
    rep = check_positions(pos, limits, dt)
    assert rep.violations == 0, rep.first
    assert float(res.profile.s_of_t(res.profile.s_of_t.x[-1])) == pytest.approx(s_end)


def test_a_path_that_differs_on_the_reused_stretch_gets_no_seam(grown):
    planner, _, _, _, _, limits, dt, pts = grown
    planner.forget()  # a fresh last plan on the original 1200 points
    machine = default_config().machine
    scale = np.asarray(machine.path_scale)
    fit = StreamingFit(2, scale, "cubic")
    fit.extend(pts[:1200])
    base = fit.path()
    plan = planner.plan(PlanRequest(base, limits, PathState(0.0), min(fit.final_length, WINDOW),
                                    dt=dt))
    bent = pts[:1600].copy()
    bent[:, 1] += 1e-3 * np.sin(np.linspace(0.0, 7.0, bent.shape[0]))  # deg
    other = fit_points(bent, scale, "cubic")
    start = state_at(plan.profile, 0.3)
    req = PlanRequest(other, limits, start, start.s + WINDOW, dt=dt)
    assert planner.find_seam(req) is None
    same = PlanRequest(base, limits, start, min(fit.final_length, start.s + WINDOW) - 1.0, dt=dt)
    assert planner.find_seam(same) is not None
