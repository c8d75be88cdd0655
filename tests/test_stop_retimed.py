"""A hold (abort, fault stop) in real time is the plan in force re-timed to rest
(`Engine._retimed` with ratio 0, `plans.warped_profile`, `engine.stop_ramps`): no planner
call at the command. The shortest-stop search it replaces took up to 16 s from hard states
of the B-spline corners and the butterfly (bench/stop_latency.py), far longer than the
real-time buffer."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.config import default_config
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState
from lookahead.protocol import Command
from lookahead.stream.engine import Engine, stop_ramps
from lookahead.stream.planners import make_planner
from lookahead.stream.plans import warped_profile
from test_override_transition import _Counting, _profile, run_to_profile_peak
from test_stream_ahead import checked, run_to_end


@pytest.mark.parametrize(("ramp", "flat", "t0"), [(0.4, 0.0, 0.37), (0.3, 0.2, 0.1),
                                                  (1.0, 0.5, 0.6), (0.05, 0.0, 0.9)])
def test_a_warp_to_rate_zero_is_a_stop_on_the_profiles_path(ramp, flat, t0) -> None:
    dt = 0.001
    prof = _profile()
    warp, t_ramp = warped_profile(prof, t0, 0.0, ramp, dt, flat)
    assert t_ramp == ramp and warp.duration == pytest.approx(ramp, abs=1e-12)
    np.testing.assert_allclose(warp.at(np.array([0.0]))[:3, 0],
                               prof.at(np.array([t0]))[:3, 0], rtol=1e-12, atol=1e-9)
    end = warp.at(np.array([warp.duration]))[:3, 0]
    # the rate falls from 1 to 0 point-symmetrically: the profile's time advanced by ramp/2
    assert end[0] == pytest.approx(float(prof.at(np.array([t0 + 0.5 * ramp]))[0, 0]),
                                   abs=1e-9)
    assert abs(end[1]) < 1e-9 and abs(end[2]) < 1e-6  # at rest
    tau = np.linspace(0.0, warp.duration, 400)
    assert np.all(warp.at(tau)[1] >= -1e-9)  # never backwards
    bx = warp.s_of_t.x[1:-1]
    for nu in range(3):
        right = np.array([warp.s_of_t(b + 1e-13, nu) for b in bx])
        left = np.array([warp.s_of_t(b - 1e-13, nu) for b in bx])
        assert np.max(np.abs(left - right)) < 1e-6 * 10**nu


@pytest.mark.parametrize(("v", "tangent"), [(1000.0, [0.7, 0.05]), (5.0, [0.1, 0.9]),
                                            (200.0, [1.0, 0.0])])
def test_the_first_stop_ramp_is_the_s_curve_at_the_tangents_limits(v, tangent) -> None:
    lim = AxisLimits(np.array([500.0, 3000.0]), np.array([2000.0, 9000.0]),
                     np.array([40000.0, 2e5]))
    ramps = stop_ramps(v, lim, np.array(tangent))
    assert [r for r, _ in ramps] == sorted(r for r, _ in ramps)  # shortest first
    ramp, flat = ramps[0]
    edge = 0.5 * (ramp - flat)
    c2 = 1.0 / (edge * (edge + flat))  # |r''| of the rate from 1 to 0
    along = np.maximum(np.abs(tangent), 1e-12)
    r1 = float(np.min(lim.amax / along)) / v
    r2 = float(np.min(lim.jmax / along)) / v
    assert c2 * edge <= r1 * (1 + 1e-9) and c2 <= r2 * (1 + 1e-9)  # |r'|, |r''|
    if ramp > 0.0101:  # (not stretched to STOP_RAMP_MIN_S) one of them is reached
        assert max(c2 * edge / r1, c2 / r2) == pytest.approx(1.0)


#: how far ahead (s) the plan in force must cruise smoothly for a hold to stop it by
#: re-timing: the re-timed stop's ramp runs over its next motion, and a feed step there (a
#: heuristic segment's cap 0.8 % lower, crossed at full jerk) lengthens it beyond the
#: braking guess
CLEAN_CRUISE_S = 0.4


def _hold_at_full_feed(engine: Engine) -> tuple[list, PathState]:
    """Run `job_segments` to the sample of the plan in force's highest feed (after 2.1 s,
    on a replan: the first plan's window ends at rest, so its feed still rises where a
    replan takes over), on to the first batch boundary from which that plan cruises
    smoothly for CLEAN_CRUISE_S, then send a hold: the batches so far."""
    batches, _, _ = run_to_profile_peak(engine, 1, skip=210)
    dt = engine.dt
    ahead = np.arange(int(CLEAN_CRUISE_S / dt))
    for _ in range(int(2.0 / (engine.batch * dt))):
        plan = engine._active.plan
        k = batches[-1].k0 + batches[-1].n
        _, _, acc, jerk = plan.profile.at(plan.times(k - 1 + ahead, dt))
        # a smooth cruise (the LP's feed swings slowly, +-130 mm/s^2 here); no feed step
        # crossed at the jerk limit (20,000 mm/s^3 and more)
        if np.max(np.abs(acc)) < 200.0 and np.max(np.abs(jerk)) < 2000.0:
            break
        batches.append(engine.next_batch())
    else:
        pytest.fail("the plan in force never cruises for CLEAN_CRUISE_S within 2 s")
    state = engine._active.plan.state(batches[-1].k0 + batches[-1].n - 1, dt)
    assert state.v > 100.0  # mm/s (X, C)
    assert engine.command(Command("hold")).ok
    return batches, state


@pytest.mark.parametrize("method", ["lp", "heuristic"])
def test_a_real_time_hold_at_full_feed_calls_no_planner(method) -> None:
    """Real time: the hold's stop is the plan in force re-timed (no stop planner call), the
    machine comes to rest within the limits, and after a resume the job runs to its end.
    Fast mode (and `warp_stops` off) still searches the shortest stop."""
    cfg = default_config()
    engine = Engine(cfg, make_planner(method), realtime=True)
    stops = [_Counting(engine.stop_planner), _Counting(engine.stop_search_planner)]
    batches, state = _hold_at_full_feed(engine)
    assert abs(state.a) < 50.0  # mm/s^2: a cruise
    for _ in range(300):
        batches.append(engine.next_batch())
    assert sum(c.calls for c in stops) == 0
    assert engine._active.plan.method == "hold"
    rest = np.vstack([b.pos for b in batches[-20:]])
    assert np.all(rest == rest[0])  # at rest within 2.8 s
    assert engine.command(Command("resume")).ok
    checked(cfg, batches + run_to_end(engine))
    assert engine.fallbacks == 0 and engine.replan_failures == 0
    for realtime in (False, True):
        other = Engine(cfg, make_planner(method), realtime=realtime)
        other.warp_stops = False
        counted = [_Counting(other.stop_planner), _Counting(other.stop_search_planner)]
        _hold_at_full_feed(other)
        other.next_batch()
        assert sum(c.calls for c in counted) > 0


def test_a_real_time_hold_while_accelerating_hard_takes_the_shorter_stop() -> None:
    """Where the plan in force accelerates hardest a re-timing can only stretch it: its
    stop is longer than the braking guess, so the search looks for a shorter one below it
    (and the re-timed stop stays where it finds none). The hold ends no later than the
    re-timed stop from the same state, within the limits."""
    from lookahead.stream.engine import stop_reach

    cfg = default_config()
    dt = cfg.machine.dt
    engine = Engine(cfg, make_planner("heuristic"), realtime=True)
    batches, k_cmd, _ = run_to_profile_peak(engine, 2, skip=1)
    job = engine._active
    state = job.plan.state(k_cmd - 1, dt)
    full = cfg.machine.limits.scaled(engine.margin)
    tangent = job.plan.path.eval_s(np.array([state.s]), order=1)[1, 0]
    retimed, _, _ = engine._retimed(job.plan, k_cmd - 1, job.tail, 0.0,
                                    stop_ramps(state.v, full, tangent), "hold")
    assert retimed.s_end - state.s > stop_reach(state, full, tangent)  # the guess rejects it
    assert engine.command(Command("hold")).ok
    for _ in range(300):
        batches.append(engine.next_batch())
    assert engine._active.plan.s_end <= retimed.s_end + 1e-9
    assert engine._active.plan.method != "hold"  # the search's (shorter) stop
    checked(cfg, batches)
