"""LP replans the way the streaming service makes them: every request starts in the state
of a sample (t = k dt) on the planner's previous plan and ends at rest one window ahead.
The planner continues its last plan there (`Seam`); stitched, the replans must pass the
finite-difference checker and lose (almost) no time against one plan of the whole job."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry import fit_points, preset_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner

WINDOW = 1400.0  # path units, ~3 braking distances at the winder's top feed


@pytest.fixture(scope="module")
def setup():
    machine = default_config().machine
    _, pts, _ = preset_points("tube-1450")
    path = fit_points(pts, np.asarray(machine.path_scale), "cubic")
    return path, machine.limits.scaled(0.98), machine.dt


def state_at(profile, t: float) -> PathState:
    """The state the service takes as a replan's start: sample t of the plan in force."""
    s, v, a, _ = profile.at(np.array([t]))[:, 0]
    return PathState(float(s), max(float(v), 0.0), float(a))


def run_chain(path, limits, dt, n_replans: int, seed: int):
    """Plan from rest, then replan from states on the plan in force after a random number
    of samples; returns the positions actually played (sampled at k dt) and the results."""
    rng = np.random.default_rng(seed)
    planner = LPPlanner()
    res = planner.plan(PlanRequest(path, limits, PathState(0.0), WINDOW, dt=dt))
    played, results, profile = [], [], res.profile
    while len(results) < n_replans:
        k = int(rng.integers(20, 80))
        if k * dt >= profile.duration:
            break
        start = state_at(profile, k * dt)
        s_end = min(path.length, start.s + WINDOW)
        end_now = float(profile.s_of_t(profile.s_of_t.x[-1]))
        if s_end <= end_now + 1e-9:  # nothing new in view: the service keeps its plan
            played.append(profile.at(np.arange(k) * dt)[0])
            profile = _shifted(profile, k * dt)
            continue
        new = planner.plan(PlanRequest(path, limits, start, s_end, dt=dt))
        results.append((start, new, profile, k))
        played.append(profile.at(np.arange(k) * dt)[0])
        profile = new.profile
    tail = np.arange(int(np.ceil(profile.duration / dt)) + 4) * dt
    played.append(profile.at(tail)[0])
    s = np.concatenate(played)
    return path.eval_s(s, 0)[0], results


def _shifted(profile, t: float):
    from lookahead.planning.profile_ops import slice_profile

    return slice_profile(profile, t)


def test_hundred_replans_on_previous_plans_all_continue_and_pass_the_checker(setup):
    path, limits, dt = setup
    pos, results = run_chain(path, limits, dt, 100, seed=5)
    assert len(results) == 100
    for start, res, _, _ in results:
        s0, v0, a0, _ = res.profile.at(np.array([0.0]))[:, 0]
        assert (s0, v0, a0) == pytest.approx((start.s, start.v, start.a), rel=1e-9, abs=1e-7)
        assert res.info["seam"] is not None  # every start lies on the last plan
    rep = check_positions(pos, limits, dt)
    assert rep.violations == 0, rep.first
    # and it moves: most of the machine's limit is used somewhere
    assert max(max(v) for v in rep.peak_fraction.values()) > 0.9


def test_whole_job_of_replans_loses_under_one_percent(setup):
    """Replans every 0.1 s (the service's period) to the end of the job."""
    path, limits, dt = setup
    planner = LPPlanner()
    profile = planner.plan(PlanRequest(path, limits, PathState(0.0), WINDOW, dt=dt)).profile
    played, every = [], 100
    while every * dt < profile.duration:
        start = state_at(profile, every * dt)
        s_end = min(path.length, start.s + WINDOW)
        played.append(profile.at(np.arange(every) * dt)[0])
        if s_end <= float(profile.s_of_t(profile.s_of_t.x[-1])) + 1e-9:
            profile = _shifted(profile, every * dt)
            continue
        profile = planner.plan(PlanRequest(path, limits, start, s_end, dt=dt)).profile
    played.append(profile.at(np.arange(int(np.ceil(profile.duration / dt)) + 1) * dt)[0])
    s = np.concatenate(played)
    assert s[-1] == pytest.approx(path.length, abs=1e-6)
    rep = check_positions(path.eval_s(s, 0)[0], limits, dt)
    assert rep.violations == 0, rep.first
    whole = LPPlanner(reuse=False).plan(PlanRequest(path, limits, PathState(0.0), path.length,
                                                    dt=dt))
    motion = (s.size - 1) * dt
    assert motion <= 1.01 * whole.profile.duration


def test_seam_replays_the_last_plan_exactly_through_its_first_interval(setup):
    path, limits, dt = setup
    planner = LPPlanner()
    first = planner.plan(PlanRequest(path, limits, PathState(0.0), WINDOW, dt=dt))
    t = 0.4567  # inside some interval, not at a node
    start = state_at(first.profile, t)
    new = planner.plan(PlanRequest(path, limits, start, start.s + WINDOW, dt=dt))
    assert new.info["seam"]["t_cut"] > 0.0
    x = new.profile.s_of_t.x
    tt = np.linspace(0.0, x[1] - x[0], 7)  # the first (cut) interval
    np.testing.assert_allclose(new.profile.at(tt)[:3], first.profile.at(t + tt)[:3],
                               rtol=1e-9, atol=1e-6)


def test_start_off_the_last_plan_is_planned_from_scratch(setup):
    path, limits, dt = setup
    planner = LPPlanner()
    first = planner.plan(PlanRequest(path, limits, PathState(0.0), WINDOW, dt=dt))
    on = state_at(first.profile, 0.3)
    off = PathState(on.s, on.v * 0.99, on.a)
    req = PlanRequest(path, limits, off, off.s + WINDOW, dt=dt)
    assert planner.find_seam(req) is None
    res = planner.plan(req)
    assert res.info["seam"] is None
    s0, v0, _, _ = res.profile.at(np.array([0.0]))[:, 0]
    assert (s0, v0) == pytest.approx((off.s, off.v), rel=1e-9)


def test_same_window_end_keeps_the_rest_of_the_last_plan(setup):
    path, limits, dt = setup
    planner = LPPlanner()
    first = planner.plan(PlanRequest(path, limits, PathState(0.0), WINDOW, dt=dt))
    start = state_at(first.profile, 0.5)
    res = planner.plan(PlanRequest(path, limits, start, WINDOW, dt=dt))
    assert res.info["seam"]["solved"] is False
    assert res.profile.duration == pytest.approx(first.profile.duration - 0.5, abs=1e-9)
    tt = np.linspace(0.0, res.profile.duration, 11)
    np.testing.assert_allclose(res.profile.at(tt)[0], first.profile.at(0.5 + tt)[0], atol=1e-6)
