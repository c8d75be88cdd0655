"""Rest-to-rest stretches of the LP's plans planned by the transient planner where it is
faster (`lp.rest_stretches`, `LPPlanner.rest_splice`).

The LP's grid loses on short, jerk-dominated moves between stops (c-polyline-deg1-30 of
the corpus: 8.12 s against the heuristic's 5.54 s). Here on polylines the corpus does not
have: three axes, other limits, other move lengths; the whole plan and a replan from inside
a replaced stretch must pass the finite-difference checker."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.geometry.nurbs import BSplinePath, CompositePath
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile, PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.rest_stretches import interior_worst, rest_spans, swap_spans
from lookahead.planning.profile_ops import concatenate, slice_profile
from lookahead.planning.sampled_check import SampledRatios
from lookahead.sampling import sample_plan

DT = 0.001
LIMITS = AxisLimits(vmax=np.array([400.0, 250.0, 60.0]), amax=np.array([3000.0, 2000.0, 500.0]),
                    jmax=np.array([60000.0, 30000.0, 8000.0]))


def polyline(seed: int, moves: int) -> CompositePath:
    """Straight 3-axis moves of 0.5-20 mm between random corners (a stop at each)."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(moves, 3))
    steps *= (rng.uniform(0.5, 20.0, size=moves) / np.linalg.norm(steps, axis=1))[:, None]
    pts = np.cumsum(np.vstack([np.zeros(3), steps]), axis=0)
    return CompositePath([BSplinePath(1, [0.0, 0.0, 1.0, 1.0], pts[i:i + 2], np.ones(3))
                          for i in range(moves)])


def whole(path) -> PlanRequest:
    return PlanRequest(path, LIMITS, PathState(0.0), path.length, dt=DT)


def violations(path, profile: FeedProfile) -> int:
    return check_positions(sample_plan(path, profile, DT).pos, LIMITS, DT).violations


@pytest.mark.parametrize("seed", [3, 17])
def test_a_polyline_plans_as_fast_as_its_moves_planned_alone(seed: int) -> None:
    path = polyline(seed, 12)
    assert path.corners_s().size == 11
    spliced = LPPlanner().plan(whole(path))
    plain = LPPlanner(rest_splice=False).plan(whole(path))
    heuristic = HeuristicPlanner(margin=1.0).plan(whole(path))
    assert spliced.info["rest_splice"]["stretches"] >= 6
    # each move is the faster of two plans: no slower than either planner's whole job
    assert spliced.profile.duration <= plain.profile.duration * 0.97
    assert spliced.profile.duration <= heuristic.profile.duration * (1.0 + 1e-6)
    end = float(spliced.profile.s_of_t(spliced.profile.s_of_t.x[-1]))
    assert end == pytest.approx(path.length, abs=1e-9)
    assert violations(path, spliced.profile) == 0


def test_a_replan_inside_a_replaced_stretch_keeps_it_to_its_stop() -> None:
    path = polyline(5, 10)
    planner = LPPlanner()
    first = planner.plan(whole(path)).profile
    used = [sp for sp in planner._stretches if sp.used]
    assert used, "no stretch was replaced"
    sp = used[len(used) // 2]
    # a state 40 % into the replaced stretch, on the plan that runs
    times = np.linspace(0.0, first.duration, 20001)
    s = first.at(times)[0]
    t = float(times[np.searchsorted(s, sp.s0 + 0.4 * (sp.s1 - sp.s0))])
    state = first.state_at(t)
    assert state.v > 0.0
    replan = planner.plan(PlanRequest(path, LIMITS, state, path.length, dt=DT))
    assert "kept_from" in replan.info["rest_splice"]
    # the same motion from there to the stretch's stop, then on to the path's end
    tail = slice_profile(first, t)
    t_stop = sp.profile.duration - replan.info["rest_splice"]["kept_from"]
    probe = np.linspace(0.0, t_stop, 200)
    np.testing.assert_allclose(replan.profile.at(probe)[0], tail.at(probe)[0], atol=1e-9)
    end = float(replan.profile.s_of_t(replan.profile.s_of_t.x[-1]))
    assert end == pytest.approx(path.length, abs=1e-9)
    joined = concatenate([slice_profile(first, 0.0, t), replan.profile])
    assert violations(path, joined) == 0


def test_without_splicing_a_replan_there_is_planned_by_the_lp() -> None:
    path = polyline(5, 10)
    planner = LPPlanner(rest_splice=False)
    first = planner.plan(whole(path)).profile
    state = first.state_at(0.37 * first.duration)
    replan = planner.plan(PlanRequest(path, LIMITS, state, path.length, dt=DT))
    assert "rest_splice" not in replan.info


class _Last:
    """The fields of `LastPlan` that `rest_spans` reads."""

    def __init__(self, n: int, stops: list[int]) -> None:
        self.stop_idx = np.array(stops, dtype=int)
        self.geo = type("Geo", (), {"n_nodes": n})()


def test_rest_spans_pair_consecutive_rest_nodes() -> None:
    last = _Last(10, [3, 7])
    assert rest_spans(last, True, True) == [(0, 3), (3, 7), (7, 9)]  # type: ignore[arg-type]
    assert rest_spans(last, False, False) == [(3, 7)]  # type: ignore[arg-type]
    assert rest_spans(_Last(10, []), True, False) == []  # type: ignore[arg-type]


def _ramp(duration: float, s0: float, s1: float) -> FeedProfile:
    """s(t) linear from s0 to s1 (at rest at neither end: only the splicing is tested)."""
    from scipy.interpolate import PPoly

    c = np.array([[0.0], [0.0], [(s1 - s0) / duration], [s0]])
    return FeedProfile(PPoly(c, np.array([0.0, duration])))


def test_swap_spans_replaces_exactly_the_given_time_spans() -> None:
    base = _ramp(3.0, 0.0, 3.0)  # s = t
    swapped = swap_spans(base, [(1.0, 2.0, _ramp(0.5, 1.0, 2.0))])
    assert swapped.duration == pytest.approx(2.5)
    np.testing.assert_allclose(swapped.at(np.array([0.5, 1.25, 1.5, 2.0]))[0],
                               [0.5, 1.5, 2.0, 2.5], atol=1e-12)


def test_interior_worst_ignores_the_samples_at_the_stretch_ends() -> None:
    t = np.array([0.0, 0.5, 1.0])
    ratios = SampledRatios(np.array([0.2, 0.4, 0.3]), np.array([0.1, 0.9, 0.1]),
                           np.array([1.3, 0.8, 1.3]), t, t, t)
    assert interior_worst(ratios, 1.0) == pytest.approx(0.9)
    assert ratios.worst == pytest.approx(1.3)
    bad = SampledRatios(ratios.vel, ratios.acc, np.array([0.1, np.nan, 0.1]), t, t, t)
    assert interior_worst(bad, 1.0) == np.inf


def test_a_stop_at_the_end_of_a_streamed_path_is_not_kept_once_the_path_goes_on() -> None:
    """The last stretch of a plan to the end of what has been received ends at rest there;
    when the next segment continues straight on (no corner), a replan from inside that
    stretch must not keep its stop: it plans on through."""
    path = polyline(11, 4)
    planner = LPPlanner()
    first = planner.plan(whole(path)).profile
    last = [sp for sp in planner._stretches if sp.used and sp.s1 == pytest.approx(path.length)]
    assert last, "the last move was not replaced"
    end = path.eval_s(np.array([path.length]), order=1)
    point, tangent = end[0, 0], end[1, 0]
    more = BSplinePath(1, [0.0, 0.0, 1.0, 1.0], np.array([point, point + 15.0 * tangent]),
                       np.ones(3))
    longer = CompositePath([*path.pieces, more])
    assert longer.corners_s().size == path.corners_s().size  # straight on: no new corner
    sp = last[0]
    times = np.linspace(0.0, first.duration, 20001)
    t = float(times[np.searchsorted(first.at(times)[0], sp.s0 + 0.5 * (sp.s1 - sp.s0))])
    replan = planner.plan(PlanRequest(longer, LIMITS, first.state_at(t), longer.length, dt=DT))
    assert "kept_from" not in replan.info.get("rest_splice", {})
    s, v = replan.profile.at(np.linspace(0.0, replan.profile.duration, 4001))[:2]
    assert np.min(v[(s > sp.s1 - 1.0) & (s < sp.s1 + 1.0)]) > 1.0  # no stop at the old end
    joined = concatenate([slice_profile(first, 0.0, t), replan.profile])
    assert violations(longer, joined) == 0
