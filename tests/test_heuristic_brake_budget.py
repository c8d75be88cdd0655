"""The compute bounds of a replan that does not plan at once (`HeuristicPlanner.plan`): the
rescue runs before the layouts' full repair rounds; the rest after each brake
target first gets the layouts' first-pass repair rounds only, the full rounds run only
where no target planned so, and a target whose brake ends where an earlier one's did is
not planned again. The states: replan-continuity states on the butterfly's first window
(braking towards its tight loops), which took 15-17 s before (the full 12 rounds failing
on the first targets, a later target's rest verifying in its first round)."""

from __future__ import annotations

import numpy as np
from bench.corpus import load_corpus

from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.stream.engine import horizon_length
from lookahead.stream.planners import make_planner


def _request(start: PathState) -> PlanRequest:
    p = load_corpus("fast", pattern="n-butterfly")[0]
    cfg, m = p.config, p.config.machine
    path = p.path()
    lim = m.limits.scaled(cfg.planner.margin)
    window = horizon_length(lim, np.asarray(m.path_scale, float), cfg.planner.horizon_s)
    return PlanRequest(path, lim, start, min(path.length, start.s + window), 0.0,
                       p.geometry().feed_cap(), m.dt)


def _counted(monkeypatch) -> tuple[list[int], list[tuple[float, float, float]]]:
    """Record the repair rounds of every layout planned and the start of every rest."""
    rounds: list[int] = []
    rests: list[tuple[float, float, float]] = []
    plan_layout = HeuristicPlanner._plan_layout
    plan_phases = HeuristicPlanner._plan_phases

    def layout(self, request, grid, vlim, limits, lay, n, *args, **kwargs):
        rounds.append(n)
        return plan_layout(self, request, grid, vlim, limits, lay, n, *args, **kwargs)

    def phases(self, request, *args, **kwargs):
        st = request.start
        rests.append((st.s, st.v, st.a))
        return plan_phases(self, request, *args, **kwargs)

    monkeypatch.setattr(HeuristicPlanner, "_plan_layout", layout)
    monkeypatch.setattr(HeuristicPlanner, "_plan_phases", phases)
    return rounds, rests


def _planned(result, request: PlanRequest) -> None:
    assert result.info["verified"]
    end = result.profile.state_at(result.profile.duration)
    assert abs(end.s - request.s_end) <= 1e-6 * request.s_end
    assert end.v <= 1e-6


def test_later_brake_target_plans_before_full_rounds_on_earlier_ones(monkeypatch):
    """Above the feed limit at 107 mm/s: the rests after the 1.0 and 0.7 targets fail
    their first-pass rounds; the 0.5 target's rest verifies, so no layout gets the full
    rounds (before: 4 layouts x 12 rounds, 14 of the 17 s). (The plan that goes on from
    the start without a brake is faster and wins, `_faster_going_on`; the brake it beat
    is in the info.)"""
    request = _request(PathState(76.6223405, 106.837168, -238.117866))
    planner = make_planner("heuristic")
    rounds, _ = _counted(monkeypatch)
    result = planner.plan(request)
    _planned(result, request)
    target = result.info.get("brake_target", result.info.get("beaten_brake_target"))
    assert target is not None
    assert target < 1.0  # the first target's rest did fail
    assert planner.repair_rounds not in rounds, rounds


def test_brake_targets_ending_in_one_state_plan_its_rest_once(monkeypatch):
    """Two brake targets above the start feed end in the same state (the start
    acceleration released at that feed): its rest is planned once, not per target."""
    request = _request(PathState(204.9138033, 65.0663128, -28.5959704))
    planner = make_planner("heuristic")
    _, rests = _counted(monkeypatch)
    result = planner.plan(request)
    _planned(result, request)
    assert "brake_target" in result.info
    assert len(rests) == len(set(rests)), rests
    assert len(rests) >= 3  # the start itself, the shared brake end, a lower target


def test_rescue_runs_before_the_full_repair_rounds(monkeypatch):
    """Braking at 59 mm/s, -394 mm/s^2 within the limits: no layout verifies in its
    first-pass rounds, the rescue's finer bands do; the full rounds (which failed here,
    2 s) are not tried first any more."""
    request = _request(PathState(206.5542781, 59.4752690, -394.347292))
    planner = make_planner("heuristic")
    rounds, _ = _counted(monkeypatch)
    result = planner.plan(request)
    _planned(result, request)
    assert result.info.get("rescue") is True
    assert planner.repair_rounds not in rounds, rounds
