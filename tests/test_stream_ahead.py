"""Replans computed ahead in real-time mode (stream/ahead.py): the plan in force keeps
producing samples while a worker computes the next plan, which takes over at a sample
chosen from the engine's inputs alone, so a worker thread and an inline computation give
the same batches."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from lookahead.checker import LimitChecker
from lookahead.config import default_config
from lookahead.planning.base import PlanRequest, PlanResult
from lookahead.protocol import Command, Segment, SetpointBatch
from lookahead.stream.ahead import (
    BRAKE_LEAD_S,
    PLAN_AHEAD_MAX_S,
    RESTART_AHEAD_S,
    ahead_samples,
)
from lookahead.stream.engine import Engine
from lookahead.stream.planners import make_planner
from lookahead.stream.plans import BRAKE_CRAWL_SHARE

AXES = ("X", "C")
#: a test that waits this long for the engine has found a deadlock (never reached when
#: the engine works: nothing below waits on the clock otherwise)
DEADLOCK_S = 60.0


def job_segments(job: str = "ahead", strokes: int = 3, n: int = 900) -> list[Segment]:
    """`strokes` 300 mm X strokes, C turning 5 turns per stroke: several windows long."""
    t = np.linspace(0.0, 1.0, n)
    pts = np.column_stack([150.0 * (1.0 - np.cos(2.0 * strokes * np.pi * t)),
                           1800.0 * strokes * t])
    chunks = [pts[i:i + 101] for i in range(0, n - 1, 100)]
    return [Segment(job, i, AXES, "points", i == len(chunks) - 1, points=c)
            for i, c in enumerate(chunks)]


class GatedPlanner:
    """A planner whose calls after the first wait until the test opens `gate`."""

    def __init__(self, method: str) -> None:
        self.inner = make_planner(method)
        self.name = self.inner.name
        self.calls = 0
        self.entered = threading.Event()  # a gated call has started
        self.gate = threading.Event()

    def plan(self, request: PlanRequest) -> PlanResult:
        self.calls += 1
        if self.calls > 1:
            self.entered.set()
            assert self.gate.wait(DEADLOCK_S), "the test never opened the gate"
        return self.inner.plan(request)

    def __getattr__(self, name: str):
        return getattr(self.inner, name)  # forget(), as the engine's planners have it


def run_until_gated(cfg, planner: GatedPlanner, pool: ThreadPoolExecutor
                    ) -> tuple[Engine, list[SetpointBatch]]:
    """A real-time engine on `job_segments` with a worker, run until a replan blocks at
    the gate: the engine and its batches so far (none final)."""
    engine = Engine(cfg, planner, realtime=True, executor=pool)
    for seg in job_segments():
        engine.submit(seg)
    batches = []
    while not planner.entered.is_set():
        batch = engine.next_batch()
        assert batch is not None and not batch.final
        batches.append(batch)
    return engine, batches


def run_to_end(engine: Engine, limit: int = 100000) -> list[SetpointBatch]:
    out: list[SetpointBatch] = []
    for _ in range(limit):
        batch = engine.next_batch()
        if batch is not None:
            out.append(batch)
            if batch.final:
                return out
    raise AssertionError("the job did not finish")


def checked(cfg, batches: list[SetpointBatch]) -> np.ndarray:
    """All positions, after asserting contiguous samples and no limit violation."""
    ks = np.concatenate([b.k0 + np.arange(b.n) for b in batches])
    assert np.array_equal(ks, np.arange(ks.size))
    pos = np.vstack([b.pos for b in batches])
    checker = LimitChecker(cfg.machine.limits, cfg.machine.dt)
    checker.feed(pos)
    assert checker.report().violations == 0
    return pos


def test_ahead_samples_are_whole_batches_within_the_shares() -> None:
    dt, batch = 0.001, 10
    assert ahead_samples(100, 100 + 60_000, batch, dt) == round(PLAN_AHEAD_MAX_S / dt)
    assert ahead_samples(100, 100 + 3000, batch, dt) == 1000  # a third of what is left
    assert ahead_samples(100, 100 + 3001, batch, dt) == 1000  # whole batches only
    assert ahead_samples(100, 100 + 29, batch, dt) == 0  # under a batch: plan now
    assert ahead_samples(100, 90, batch, dt) == round(RESTART_AHEAD_S / dt)  # at rest
    # as late as BRAKE_LEAD_S before the plan's final braking, where that is later
    lead = round(BRAKE_LEAD_S / dt)
    assert ahead_samples(100, 3100, batch, dt, k_brake=2600) == 2500 - lead
    assert ahead_samples(100, 3100, batch, dt, k_brake=1000) == 1000  # the share
    assert ahead_samples(100, 3100, batch, dt, k_brake=2605) == 2500 - lead  # whole batches
    # no cap once the job's geometry is all in (the engine passes cap_s=None then)
    far = 100 + round(60.0 / dt)
    assert ahead_samples(100, far, batch, dt, k_brake=far) == round(PLAN_AHEAD_MAX_S / dt)
    assert ahead_samples(100, far, batch, dt, k_brake=far,
                         cap_s=None) == far - 100 - lead


@pytest.mark.parametrize("method", ["heuristic", "lp"])
def test_braking_from_is_where_the_final_deceleration_starts(method: str) -> None:
    """`CommittedPlan.braking_from`: the path acceleration is < 0 from there to the
    plan's rest, and >= 0 just before (a plan that accelerates first)."""
    cfg = default_config()
    engine = Engine(cfg, make_planner(method), realtime=True)
    for seg in job_segments():
        engine.submit(seg)
    assert engine.next_batch() is not None
    plan = next(iter(engine._jobs.values())).plan
    assert plan is not None and plan.k_end > plan.k_plan + 100
    dt = cfg.machine.dt
    k_brake = plan.braking_from(dt)
    acc = plan.profile.at(plan.times(np.arange(plan.k_plan + 1, plan.k_end), dt))[2]
    vel = plan.profile.at(plan.times(np.arange(plan.k_plan + 1, plan.k_end), dt))[1]
    i = k_brake - plan.k_plan - 1
    assert 0 < i < acc.size
    moving = vel[i:] > BRAKE_CRAWL_SHARE * np.max(vel)
    assert np.all(acc[i:][moving] < 0.0) and acc[i - 1] >= 0.0
    assert plan.k_end - k_brake > 50  # a braking, not a rounding


def test_braking_from_skips_the_crawl_into_rest() -> None:
    """A plan that brakes from 100 mm/s to a crawl of ~1.7 mm/s whose acceleration swings
    around 0 before it stops (an LP window's plan into its end, seen on
    cam-feed-w3-F6000-L300-R100-a45-hoop): the final braking starts where the feed leaves
    100 mm/s, not in the crawl. Taken as the crawl's last a >= 0, the real-time take-over
    fell 0.3 s before the end, deep in the braking: dips to 5 mm/s mid-stroke."""
    from scipy.interpolate import CubicSpline

    from lookahead.geometry import fit_points
    from lookahead.planning.base import FeedProfile
    from lookahead.stream.plans import CommittedPlan

    dt = 0.001
    t = np.arange(0.0, 1.3, dt)
    v = np.interp(t, [0.0, 1.0, 1.05, 1.25, 1.3], [100.0, 100.0, 1.7, 1.7, 0.0])
    v[(t > 1.1) & (t < 1.2)] += 0.05 * np.sin(2 * np.pi * (t[(t > 1.1) & (t < 1.2)] - 1.1) / 0.05)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    profile = FeedProfile(CubicSpline(t, s))
    path = fit_points(np.column_stack([np.linspace(0, 200, 50), np.zeros(50)]),
                      np.ones(2))
    plan = CommittedPlan(path, profile, 0, float(s[-1]), t.size - 1, 0.0, "test")
    k_brake = plan.braking_from(dt)
    acc = profile.at(t)[2]
    assert np.any(acc[(t > 1.1) & (t < 1.2)] >= 0.0)  # the crawl's acceleration swings
    assert 995 <= k_brake <= 1005


@pytest.mark.parametrize("method", ["heuristic", "lp"])
def test_a_worker_thread_gives_the_batches_of_an_inline_engine(method: str) -> None:
    """The same job through a real-time engine computing replans at once and through one
    with a worker thread: bit-identical samples, several replans taken over ahead."""
    cfg = default_config()
    runs = []
    for executor in (None, ThreadPoolExecutor(max_workers=1)):
        engine = Engine(cfg, make_planner(method), realtime=True, executor=executor)
        for seg in job_segments():
            engine.submit(seg)
        runs.append((run_to_end(engine), engine.replans, engine.fallbacks))
        if executor is not None:
            executor.shutdown()
    (inline, replans, fallbacks), (threaded, replans_t, fallbacks_t) = runs
    assert replans == replans_t >= 3 and fallbacks == fallbacks_t == 0
    assert np.array_equal(checked(cfg, inline), checked(cfg, threaded))


def test_samples_keep_coming_while_a_replan_is_computed() -> None:
    """While the worker's replan is blocked, the plan in force keeps producing batches (in
    fast mode the first batch after the replan's start would wait for it)."""
    cfg = default_config()
    planner = GatedPlanner("heuristic")
    with ThreadPoolExecutor(max_workers=1) as pool:
        engine, batches = run_until_gated(cfg, planner, pool)
        k_asked = batches[-1].k0 + batches[-1].n - 1
        for _ in range(30):  # 0.3 s of samples (it takes over ~0.4 s ahead), still blocked
            batches.append(engine.next_batch())
        assert not planner.gate.is_set()
        assert batches[-1].k0 + batches[-1].n - 1 == k_asked + 300
        planner.gate.set()
        batches += run_to_end(engine)
    assert engine.replans >= 2 and engine.fallbacks == 0 and engine.replan_failures == 0
    checked(cfg, batches)


def test_a_hold_during_a_replan_under_way_stops_without_waiting_for_it() -> None:
    """A hold while the worker's replan is blocked: the stop is planned and produced at
    once (the worker's fallback is not the stop planner), the machine comes to rest; after
    the gate opens and a resume, the job runs to its end within the limits."""
    cfg = default_config()
    planner = GatedPlanner("heuristic")
    with ThreadPoolExecutor(max_workers=1) as pool:
        engine, batches = run_until_gated(cfg, planner, pool)
        assert engine.command(Command("hold")).ok
        for _ in range(300):  # 3 s: the stop from full feed takes well under that
            batches.append(engine.next_batch())
        assert not planner.gate.is_set()
        assert engine.status().state == "holding"
        rest = np.vstack([b.pos for b in batches[-10:]])
        assert np.all(rest == rest[0])  # at rest, the replan still blocked
        planner.gate.set()
        assert engine.command(Command("resume")).ok
        batches += run_to_end(engine)
    assert engine.fallbacks == 0 and engine.replan_failures == 0
    checked(cfg, batches)


def test_an_override_during_an_lp_replan_under_way_is_bridged_at_once() -> None:
    """An override while the worker's LP replan is blocked: the stop planner plans the new
    feed at once (a bridge, not a fallback), batches keep coming at the new override
    without waiting for the worker; once the gate opens the LP's replan computed ahead
    takes over from the bridge's state, and the job finishes within the limits with no
    fallback. In fast mode the override is the LP's own plan, made at once."""
    cfg = default_config()
    planner = GatedPlanner("lp")
    with ThreadPoolExecutor(max_workers=1) as pool:
        engine, batches = run_until_gated(cfg, planner, pool)
        calls = planner.calls
        assert engine.command(Command("override", 0.5)).ok
        for _ in range(30):  # 0.3 s of samples while the LP is still blocked
            batches.append(engine.next_batch())
        assert not planner.gate.is_set() and planner.calls == calls
        assert engine.bridges == 1
        assert engine.status().override == 0.5
        planner.gate.set()
        batches += run_to_end(engine)
    assert planner.calls > calls + 1  # the blocked replan, then the LP's after the bridge
    assert engine.fallbacks == 0 and engine.replan_failures == 0
    checked(cfg, batches)
    fast = Engine(cfg, make_planner("lp"))
    for seg in job_segments():
        fast.submit(seg)
    for _ in range(50):
        fast.next_batch()
    assert fast.command(Command("override", 0.5)).ok
    run_to_end(fast)
    assert fast.bridges == 0


def new_take_overs(engine: Engine, calls: int = 1_000_000):
    """Run a real-time engine up to its final batch (at most `calls` calls); yield (the
    last produced sample, the plan in force, the replan under way) for each new replan."""
    pending = None
    for _ in range(calls):
        batch = engine.next_batch()
        if batch is None:
            continue
        job = engine._jobs.get(batch.job)
        now = None if job is None else job.pending
        if now is not None and now is not pending:
            yield batch.k0 + batch.n - 1, job.plan, now
        pending = now
        if batch.final:
            return


def _take_over_leads(feed: float | None, horizon_s: float | None = None) -> list[int]:
    """Samples between each replan's request and its take-over, in a real-time engine on
    `job_segments` (all received at once) with every segment's feed capped at `feed`
    (`horizon_s`: the planner's look-ahead, default the configuration's)."""
    from dataclasses import replace as with_

    cfg = default_config()
    if horizon_s is not None:
        cfg = with_(cfg, planner=with_(cfg.planner, horizon_s=horizon_s))
    engine = Engine(cfg, make_planner("heuristic"), realtime=True)
    for seg in job_segments():
        engine.submit(with_(seg, feed=feed))
    return [pending.k_at - k_last for k_last, _, pending in new_take_overs(engine, 20000)]


def test_once_the_geometry_is_in_a_replan_may_take_over_beyond_the_cap() -> None:
    """A slow job (feed 20 mm/s, a look-ahead of 30 s: plans of tens of seconds) whose
    segments are all in: replans take over more than PLAN_AHEAD_MAX_S ahead (there is no
    geometry to wait for), still before the plan in force's final braking (the job runs
    to its end). (At the default 2 s the feed-capped windows hold 2 s of motion.)"""
    cap = round(PLAN_AHEAD_MAX_S / default_config().machine.dt)
    leads = _take_over_leads(20.0, horizon_s=30.0)
    assert leads and max(leads) > cap


def test_take_overs_avoid_the_plan_in_forces_hard_braking(monkeypatch) -> None:
    """Real time: a replan computed ahead takes over where the plan in force does not
    decelerate (above TAKE_OVER_BRAKING_SHARE of its strongest deceleration), where a
    whole batch between half of `ahead_samples`' lead and all of it allows. On the
    feed-capped F20000 winding program with the LP, the plain take-overs (0.2 s before
    the plan's final braking) fell in its slowdown 107 times of 110; replans from braking
    states were the LP's slowest and least robust. Since the LP's envelope into a window's
    end follows the tangent there (stop 44, `lp.envelope.rest_envelope`) its braking is
    shorter: 5 plain take-overs of 94 fell in it, 1 with the rule (measured at stop 44,
    `REST_CURVATURE_SHARE` 0.1)."""
    from bench.corpus import load_corpus

    import lookahead.stream.engine as engine_module

    p = load_corpus("all", pattern="cam-feed-w3-F20000-*")[0]
    share = engine_module.TAKE_OVER_BRAKING_SHARE

    def take_overs() -> tuple[int, int]:
        """(take-overs, how many of them in the plan in force's hard braking)."""
        engine = Engine(p.config, make_planner("lp"), realtime=True)
        for seg in p.segments:
            engine.submit(seg)
        hard = [bool(plan.braking_hard(np.array([pending.k_at]), engine.dt, share)[0])
                for _, plan, pending in new_take_overs(engine)]
        return len(hard), sum(hard)

    count, hard = take_overs()
    assert count >= 50 and hard <= 2
    monkeypatch.setattr(engine_module, "TAKE_OVER_BRAKING_SHARE", float("inf"))
    count_off, hard_off = take_overs()  # the rule off: no state counts as braking
    assert count_off >= 50 and hard_off > hard
