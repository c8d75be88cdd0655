"""Heuristic replans that continue the last plan (issue 14, `heuristic.continuation`).

The service replans the heuristic from a state of its last plan every window. Planned
afresh on a new grid, such a replan could crawl where the last plan did not: on
cam-style-R100-a30-L600 the engine wound 26.0 s against 18.8 s for the same heuristic
on the whole job (replans from 1167 mm/s braking at 1000 mm/s^2, above the default
shares' feed limit, took a brake to half the limit and then 4 s at 144 mm/s), and on
cam-fp-hel25 a replan 1.4 mm before a tight bend crawled 300 mm at 119 mm/s.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from bench.corpus import load_corpus
from bench.corpus_bench import engine_batches, run_engine, run_whole

from corpus_windows import first_window
from lookahead.checker import LimitChecker
from lookahead.planning.base import FeedCap
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic.continuation import (
    LastPlan,
    prefix_within_limits,
    seam_state,
    seam_time,
    start_time,
    time_at_s,
)
from lookahead.planning.heuristic.path_limits import BudgetShares
from lookahead.planning.profile_ops import slice_profile
from lookahead.stream.engine import Engine


def test_windowed_heuristic_keeps_the_whole_jobs_pace():
    """The engine's windowed heuristic (fast mode, as `serve --fast` runs it) winds
    cam-style-R100-a30-L600 within 1 % of the whole-job heuristic (it took 38.5 % longer),
    with 0 violations of the independent checker, 0 fallbacks and 0 failed replans."""
    p = load_corpus("all", pattern="cam-style-R100-a30-L600")[0]
    engine = run_engine(p, "engine-heuristic")
    whole = run_whole(p, "heuristic")
    assert engine["violations"] == 0 and whole["violations"] == 0
    assert engine["fallbacks"] == 0 and engine["replan_failures"] == 0
    assert engine["winding_s"] <= 1.01 * whole["winding_s"], (engine["winding_s"],
                                                              whole["winding_s"])


@pytest.fixture(scope="module")
def tube_window():
    """The first window of the fast corpus's tube and the planner that planned it."""
    first = first_window("w-issue-tube1450-R100-a45-sine-2mm")
    planner = HeuristicPlanner(margin=1.0)
    result = planner.plan(first.request)
    return first, planner, result


def test_a_start_on_the_last_plan_is_found_and_its_seam_is_a_cruise(tube_window):
    """`start_time` finds a start taken from the last plan at its own time, refuses one
    off the plan (feed 1 % higher) and one under other limits; `seam_time` is a later
    piece start with path acceleration 0 and a positive feed."""
    first, _, result = tube_window
    last = LastPlan(first.request, result.profile)
    t = 0.3 * result.profile.duration
    state = seam_state(result.profile, t)
    on = replace(first.request, start=state)
    assert start_time(last, on) == pytest.approx(t, abs=1e-9)
    off = replace(first.request, start=replace(state, v=1.01 * state.v))
    assert start_time(last, off) is None
    other = replace(on, limits=first.request.limits.scaled(0.9))
    assert start_time(last, other) is None
    t_seam = seam_time(result.profile, t, first.dt)
    assert t_seam is not None and t_seam >= t + first.dt
    seam = seam_state(result.profile, t_seam)
    assert seam.v > 0.0 and abs(seam.a) < 1e-6 * float(np.max(first.limits.amax))
    assert time_at_s(result.profile, seam.s) == pytest.approx(t_seam, abs=1e-9)


def test_the_kept_part_is_checked_against_the_new_requests_caps(tube_window):
    """The kept part of the last plan passes the check on its own request, and is
    refused under a feed cap below its feed (new segments' `feed` fields) and under
    lower limits."""
    first, _, result = tube_window
    t0 = 0.2 * result.profile.duration
    t1 = seam_time(result.profile, t0, first.dt)
    assert t1 is not None
    prefix = slice_profile(result.profile, t0, t1)
    request = replace(first.request, start=seam_state(result.profile, t0))
    shares = BudgetShares()
    assert prefix_within_limits(request, prefix, shares, None)
    v_top = float(np.max(prefix.at(np.linspace(0.0, prefix.duration, 200))[1]))
    cap = FeedCap(np.array([0.0, first.path.length]), np.array([0.9 * v_top]))
    assert not prefix_within_limits(replace(request, feed_cap=cap), prefix, shares, None)
    slower = replace(request, limits=first.request.limits.scaled(0.5))
    assert not prefix_within_limits(slower, prefix, shares, None)


class Recorder:
    """A planner that keeps every request and result (the engine's replans)."""

    def __init__(self, inner: HeuristicPlanner) -> None:
        self.inner = inner
        self.calls: list = []

    def plan(self, request):
        result = self.inner.plan(request)
        self.calls.append((request, result))
        return result

    def __getattr__(self, item: str):
        return getattr(self.inner, item)


@pytest.fixture(scope="module")
def rand4_engine():
    """c-rand4-xyza-1500pts (a 4-axis random path) through the engine in fast mode: the
    planner's calls, the checker's report and the whole-job heuristic's winding time."""
    p = load_corpus("all", pattern="c-rand4-xyza-1500pts")[0]
    m = p.config.machine
    recorder = Recorder(HeuristicPlanner(margin=1.0))
    engine = Engine(p.config, recorder)
    for seg in p.segments:
        engine.submit(seg)
    checker = LimitChecker(m.limits, m.dt)
    samples = 0
    for batch in engine_batches(engine):
        checker.feed(batch.pos)
        samples += batch.n
    return recorder, engine, checker.report(), (samples - 1) * m.dt, run_whole(p, "heuristic")


def test_replans_continue_the_last_plan_where_it_was_faster(rand4_engine):
    """Some replan of c-rand4 keeps its last plan up to a seam (the fresh replan there lost
    6 %: 5.813 s against 5.478 s joined); each joined plan follows the last plan exactly up
    to the seam and takes less time than a new planner's plan of the same request; the
    stream passes the checker with 0 fallbacks, and the windowed heuristic winds within
    1 % of the whole-job heuristic."""
    recorder, engine, report, winding, whole = rand4_engine
    assert report.violations == 0 and engine.fallbacks == 0 and engine.replan_failures == 0
    assert winding <= 1.01 * whole["winding_s"], (winding, whole["winding_s"])
    joined = [(k, req, res) for k, (req, res) in enumerate(recorder.calls)
              if "continued_s" in res.info]
    assert joined
    for k, request, result in joined:
        last_request, last = recorder.calls[k - 1]
        t0 = start_time(LastPlan(last_request, last.profile), request)
        assert t0 is not None
        s_seam = request.start.s + result.info["continued_s"]
        t_seam = time_at_s(result.profile, s_seam)
        ts = np.linspace(0.0, t_seam, 50)
        kept = result.profile.at(ts)[0]
        before = last.profile.at(ts + t0)[0]
        np.testing.assert_allclose(kept, before, rtol=0, atol=1e-9 * max(s_seam, 1.0))
        fresh = HeuristicPlanner(margin=1.0).plan(request)
        assert result.profile.duration < fresh.profile.duration


def test_forget_drops_the_last_plan(rand4_engine):
    """After `forget()` (the engine's dropped take-overs and overrides) a request that
    was joined onto the last plan is planned afresh."""
    recorder, *_ = rand4_engine
    k, request = next((k, req) for k, (req, res) in enumerate(recorder.calls)
                      if "continued_s" in res.info)
    planner = HeuristicPlanner(margin=1.0)
    planner.plan(recorder.calls[k - 1][0])
    planner.forget()
    assert planner._last is None
    assert "continued_s" not in planner.plan(request).info
