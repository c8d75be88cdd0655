"""Heuristic replans from states on its own plan (issues 13 and 14): the service replans
from wherever its last plan is, so every state of a heuristic plan must be a start the
heuristic plans from. Here: the braking to rest at the end of the butterfly's first window
under feed-level budgets, where a replan's grid samples the path at other points than the
plan's, so the start lies a hair outside the replan's own fastest braking
(`scan._land_in_first`; before it: "no free-junction chain" for every layout)."""

from __future__ import annotations

import numpy as np
import pytest
from bench.corpus import load_corpus

from corpus_windows import FirstWindow, first_window
from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanningError, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.sampling import sample_plan
from lookahead.stream.engine import horizon_length
from lookahead.stream.planners import make_planner
from lookahead.stream.plans import plan_checked

#: share of the first plan's duration at its end replanned from (its braking to rest)
END_SHARE = 0.02


@pytest.fixture(scope="module")
def butterfly_end() -> tuple[FirstWindow, np.ndarray]:
    """The butterfly's first window and the sample indices of the braking at its end."""
    first = first_window("n-butterfly")
    n = first.samples
    return first, np.arange(int((1.0 - END_SHARE) * n), n - 1)


def test_replans_from_the_braking_to_rest_at_the_window_end(butterfly_end):
    """Every sample of the first plan's braking to rest (it ends the path) is a start the
    heuristic replans from, and the engine's check (continuity with the samples already
    published, the independent checker at the limits) accepts the replan."""
    first, ks = butterfly_end
    limits = first.corpus.config.machine.limits
    failed, moving = [], 0
    for k in ks.tolist():
        request, tail = first.replan(k)
        st = request.start
        if st.s >= first.path.length - 1e-9 * first.path.length:
            continue
        moving += st.v > 0
        try:
            plan_checked(make_planner("heuristic"), request, k, tail, limits)
        except (PlanningError, ValueError, RuntimeError, ArithmeticError) as exc:
            failed.append((k, st, str(exc)[:120]))
    assert moving > 50  # the braking is sampled, not just the rest at its end
    assert not failed, failed[:3]


def test_replan_accelerating_into_a_corner_passes_the_checker():
    """Found by bench/replan_continuity.py (stop 25) on a state of the valley heuristic's
    first window of c-corners-bspline-2d, and planned the same way without valleys: from
    s = 173.454 at 26.55 mm/s, +128 mm/s^2 (above the first segment's cap: the plan brakes
    first), one window on. The brakes to a fraction of the feed limit (`Brake.brake`, 48-50
    mm long at their time-scaled limits) ran through the corner at s = 180.589, where the
    machine must be at rest: the plan passed it at 46 mm/s, 23x jmax (X jerk 915,091
    mm/s^3 against 40,000, refused by the engine's checker) though the heuristic's grid
    check passed it. Such brakes are refused (`planner._first_corner`); the plan stops at
    the corner instead (`Brake.stop_at`) and goes on from rest there."""
    p = load_corpus("fast", pattern="c-corners-bspline-2d")[0]
    cfg, m = p.config, p.config.machine
    path = p.path()
    lim = m.limits.scaled(cfg.planner.margin)
    window = horizon_length(lim, np.asarray(m.path_scale, float), cfg.planner.horizon_s)
    start = PathState(173.45435485684342, 26.550243909589, 128.02939450463606)
    request = PlanRequest(path, lim, start, min(path.length, start.s + window), 0.0,
                          p.geometry().feed_cap(), m.dt)
    try:
        plan_checked(make_planner("heuristic"), request, 0, np.empty((0, 2)), m.limits)
    except PlanningError as exc:
        pytest.fail(str(exc))


#: every how many samples of the dome's valley motions a replan starts (a compute bound:
#: ~0.15 s a replan; the valleys of the first window span 416 samples)
VALLEY_STRIDE = 8


@pytest.fixture(scope="module")
def dome_first_window() -> tuple[FirstWindow, np.ndarray]:
    """The polar dome's first window and the samples of its plan whose feed lies above the
    feed limit where they are: inside a valley motion (`heuristic.valley`)."""
    first = first_window("w-polar-dome-*")
    grid, vlim = HeuristicPlanner(margin=1.0)._grid(first.request, first.request.start,
                                                    first.limits)
    ks = np.arange(first.samples)
    s, v = np.array([[first.plan.state(int(k), first.dt).s,
                      first.plan.state(int(k), first.dt).v] for k in ks]).T
    cell = np.clip(np.searchsorted(grid.edges, s) - 1, 0, grid.ncells - 1)
    return first, ks[v > vlim[cell]]


def test_replans_from_inside_a_valley_above_the_caps(dome_first_window):
    """Found by bench/replan_continuity.py (stop 26) on the polar dome: a replan from a
    state inside a valley motion of the heuristic's own first window (feed above the
    caps, decelerating into the bend) was refused ("no brake within the limits from
    v=105.05, a=-563.033"; here 19 of the 52 samples, all in the first valley, from
    its descent to just past its apex): such a start was only ever braked, and no brake
    fits the limits there. The plan now continues the valley from the start
    (`valley.start_valley`). Every VALLEY_STRIDE-th sample above the caps is a start the
    heuristic replans from, and the engine's check accepts it."""
    first, ks = dome_first_window
    assert ks.size > 100  # the valleys are sampled
    failed = []
    planner = make_planner("heuristic")
    for k in ks[::VALLEY_STRIDE].tolist():
        request, tail = first.replan(k)
        try:
            plan_checked(planner, request, k, tail, first.corpus.config.machine.limits)
        except (PlanningError, ValueError, RuntimeError, ArithmeticError) as exc:
            failed.append((k, request.start, str(exc)[:120]))
    assert not failed, (len(failed), failed[:3])


@pytest.mark.parametrize("start", [
    PathState(142.06645804913333, 105.04978263889089, -563.0332576676653),
    PathState(145.44643150781025, 89.4655274751399, -327.49560883239303)])
def test_replan_decelerating_inside_a_valley_passes_the_checker(start):
    """The two refused states of bench/replan_continuity.py on w-polar-dome-R30-a5-0p5mm
    (seed 1: samples 610 and 645 of the first window, 1.3-1.4x the feed limits of 81 and
    62 mm/s there), planned one window on: a verified plan that continues the valley (no
    brake first), its sampled stream within the checker's limits."""
    p = load_corpus("fast", pattern="w-polar-dome-*")[0]
    cfg, m = p.config, p.config.machine
    path = p.path()
    lim = m.limits.scaled(cfg.planner.margin)
    window = horizon_length(lim, np.asarray(m.path_scale, float), cfg.planner.horizon_s)
    request = PlanRequest(path, lim, start, min(path.length, start.s + window), 0.0,
                          p.geometry().feed_cap(), m.dt)
    result = make_planner("heuristic").plan(request)
    assert result.info["verified"] and "brake_scale" not in result.info
    assert result.info.get("valley_segments", 0) > 0
    report = check_positions(sample_plan(path, result.profile, m.dt).pos, m.limits, m.dt)
    assert report.ok, report.first
