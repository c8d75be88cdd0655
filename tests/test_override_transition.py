"""An override in real time is bridged by the plan in force re-timed (`Engine._warp_bridge`,
`plans.warped_profile`): no planner call at the command (a heuristic bridge from a hard
state took seconds on the B-spline corners, longer than the buffer), the samples within the
limits, the new override's limits in force from the end of the ramp on."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline, PPoly

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile
from lookahead.protocol import Command
from lookahead.stream.engine import Engine
from lookahead.stream.planners import make_planner
from lookahead.stream.plans import warped_profile
from test_stream_ahead import checked, job_segments, run_to_end


def _profile() -> FeedProfile:
    """A C2 piecewise cubic s(t) with an increasing s (feed 10 +- 3)."""
    rng = np.random.default_rng(0)
    x = np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 0.3, 12))])
    cs = CubicSpline(x, 10.0 * x + np.sin(3.0 * x))
    return FeedProfile(PPoly(cs.c, cs.x))


@pytest.mark.parametrize(("ratio", "ramp", "t0"), [(0.6, 0.4, 0.37), (1.5, 0.3, 0.1),
                                                    (0.6, 5.0, 0.2), (1.0, 0.2, 0.5)])
def test_warped_profile_ramps_then_is_the_profile_time_scaled(ratio, ramp, t0) -> None:
    dt = 0.001
    prof = _profile()
    warp, t_ramp = warped_profile(prof, t0, ratio, ramp, dt)
    start, orig = warp.at(np.array([0.0]))[:3, 0], prof.at(np.array([t0]))[:3, 0]
    np.testing.assert_allclose(start, orig, rtol=1e-12, atol=1e-9)
    end = warp.at(np.array([warp.duration]))[:, 0]
    assert end[0] == pytest.approx(prof.at(np.array([prof.duration]))[0, 0], abs=1e-9)
    assert warp.s_of_t.c.shape[0] - 1 <= 5  # warps in turn do not multiply the degree
    # s, v, a continuous at every breakpoint
    bx = warp.s_of_t.x[1:-1]
    for nu in range(3):
        right = np.array([warp.s_of_t(b + 1e-13, nu) for b in bx])
        left = np.array([warp.s_of_t(b - 1e-13, nu) for b in bx])
        assert np.max(np.abs(left - right)) < 1e-6 * 10**nu
    if t_ramp < warp.duration:  # after the ramp: the profile time-scaled by `ratio`
        tau = np.linspace(t_ramp, warp.duration, 50)
        t_at = t0 + 0.5 * (1.0 + ratio) * ramp  # the profile's time at the ramp's end
        want = prof.at(np.minimum(t_at + ratio * (tau - t_ramp), prof.duration))
        got = warp.at(tau)
        np.testing.assert_allclose(got[0], want[0], atol=1e-9)
        np.testing.assert_allclose(got[1], ratio * want[1], atol=1e-8)
        np.testing.assert_allclose(got[2], ratio**2 * want[2], atol=1e-6)


def run_to_profile_peak(engine: Engine, nu: int, skip: int = 40
                        ) -> tuple[list, int, float]:
    """Submit `job_segments`, take `skip` batches, then run to the first batch boundary at
    or before the sample where the plan in force's derivative `nu` (1: feed, 2: path
    acceleration) is highest within 1.5 s: the batches so far, that sample, the peak.
    Where a replan takes over on the way, the peak is looked for again on it."""
    cfg = engine.config
    dt = cfg.machine.dt
    for seg in job_segments():
        engine.submit(seg)
    batches = [engine.next_batch() for _ in range(skip)]
    while True:
        plan = engine._active.plan
        k_now = batches[-1].k0 + batches[-1].n
        ks = np.arange(k_now, min(plan.k_end, k_now + 1500))
        values = plan.profile.at(plan.times(ks, dt))[nu]
        k_cmd = int(ks[np.argmax(values)])
        k_cmd -= k_cmd % cfg.service.batch
        while batches[-1].k0 + batches[-1].n < k_cmd and engine._active.plan is plan:
            batches.append(engine.next_batch())
        if engine._active.plan is plan:
            return batches, k_cmd, float(np.max(values))


class _Counting:
    """Counts the calls of a planner's `plan`."""

    def __init__(self, planner) -> None:
        self.calls = 0
        inner = planner.plan

        def plan(request):
            self.calls += 1
            return inner(request)

        planner.plan = plan


@pytest.mark.parametrize("method", ["lp", "heuristic"])
def test_an_override_down_at_full_acceleration_plans_nothing_at_the_command(method) -> None:
    """Real time, override 1.0 -> 0.6 where the plan accelerates hardest: the batch after
    the command calls no stop planner (before: the heuristic bridge, then a stop search
    where it failed); the bridge is the plan in force re-timed, the stream passes the
    checker at the limits and, from the end of the ramp, at the new override's limits;
    the configured planner takes over later; no fallback, no failed replan."""
    cfg = default_config()
    dt = cfg.machine.dt
    engine = Engine(cfg, make_planner(method), realtime=True)
    stops = [_Counting(engine.stop_planner), _Counting(engine.stop_search_planner)]
    # the sample of the highest path acceleration in the plan in force, past the start
    batches, k_cmd, peak = run_to_profile_peak(engine, 2)
    state = engine._active.plan.state(k_cmd - 1, dt)
    assert state.a > 0.5 * peak
    assert engine.command(Command("override", 0.6)).ok
    batches.append(engine.next_batch())
    assert sum(c.calls for c in stops) == 0
    bridge = engine._active.plan
    assert bridge.method == "override" and engine.bridges == 1
    pos = checked(cfg, batches + run_to_end(engine))
    assert engine.fallbacks == 0 and engine.replan_failures == 0
    assert engine.replans >= 3  # the configured planner took over from the bridge
    # from the end of the longest ramp on the new limits hold (the old plan time-scaled,
    # then the configured planner's plans at 0.6)
    lim = cfg.machine.limits
    f = 0.6
    slow = AxisLimits(lim.vmax * f, lim.amax * f * f, lim.jmax * f**3)
    k_ramp = k_cmd + round(1.6 / dt)
    assert check_positions(pos[k_ramp - 3:], slow, dt).ok
