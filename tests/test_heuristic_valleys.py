"""Valleys (`heuristic.valley`): tight bends passed by one motion of positive path jerk
instead of a cruise at the planning segments' caps, planned inside the backward scan (it
restarts at the motion's entry and exit states) and followed by the forward chain."""

from __future__ import annotations

import numpy as np
import pytest
from bench.corpus import load_corpus

from lookahead.checker import check_positions
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic import planner as heuristic_planner
from lookahead.planning.heuristic.levels import level_budgets
from lookahead.planning.heuristic.path_limits import choose_segments, feed_limit, segment_budgets
from lookahead.planning.heuristic.scan import neighbour_min
from lookahead.planning.heuristic.split import split_by_loss
from lookahead.planning.heuristic.valley import find_valleys
from lookahead.planning.heuristic.zero_junctions import junction_caps
from lookahead.sampling import sample_plan


@pytest.fixture(scope="module")
def dome():
    """The fast corpus's polar dome (0.5 mm points): its bends are the valleys' case."""
    p = load_corpus("fast", pattern="w-polar-dome-*")[0]
    path = p.path()
    request = PlanRequest(path, p.config.machine.limits.scaled(p.config.planner.margin),
                          PathState(0.0), path.length, feed_cap=p.geometry().feed_cap(),
                          dt=p.config.machine.dt)
    return p, request


def test_dome_passes_its_bends_in_valleys(dome):
    """With valleys the dome winds 8 % faster (2.181 s -> 1.996 s; the windowed LP:
    1.789 s), the plan verified and its sampled stream within the checker's limits."""
    p, request = dome
    result = HeuristicPlanner(margin=1.0).plan(request)
    assert result.info["verified"] and result.info.get("valley_segments", 0) > 0
    assert result.profile.duration < 2.05
    m = p.config.machine
    report = check_positions(sample_plan(request.path, result.profile, m.dt).pos, m.limits,
                             m.dt)
    assert report.ok, report.first
    without = HeuristicPlanner(margin=1.0, valleys=False).plan(request)
    assert without.profile.duration > 1.05 * result.profile.duration


def test_valley_motions_stay_within_the_limits(dome):
    """Every valley motion, sampled densely, keeps the signed axis velocity, acceleration
    and jerk within the limits, passes its apex above the caps of the segments it spans,
    and enters and leaves within its neighbours' caps."""
    _, request = dome
    planner = HeuristicPlanner(margin=1.0)
    limits = request.limits
    grid, _ = planner._grid(request, request.start, limits)
    layout = heuristic_planner.COARSE_WIDE
    vlim = feed_limit(grid, limits, layout.shares, request.feed_cap)
    starts = choose_segments(grid, vlim, layout.band_ratio)
    rule = layout.split
    starts = split_by_loss(grid.edges, vlim, starts, rule.rel_loss, rule.abs_dt * request.dt,
                           rule.step)
    b = segment_budgets(grid, starts, vlim, limits, layout.shares)
    b, levels = level_budgets(grid, starts, vlim, limits, layout.shares, b, None, None,
                              layout.levels)
    cap = junction_caps(request, grid, starts, b)
    valleys = find_valleys(grid, starts, b, levels, vlim, cap, limits, layout.shares,
                           neighbour_min(b.J))
    assert len(valleys) >= 2
    above = 0.0
    for vy in valleys:
        T = float(vy.phases.duration[0])
        t = np.linspace(0.0, T, 400)
        j = float(vy.phases.jerk[0])
        a0, v0, s0 = float(vy.phases.acc[0]), float(vy.phases.vel[0]), float(vy.phases.pos[0])
        s = s0 + v0 * t + a0 * t**2 / 2 + j * t**3 / 6
        v = (v0 + a0 * t + j * t**2 / 2)[:, None]
        a = (a0 + j * t)[:, None]
        _, xs, xss, xsss = request.path.eval_s(s, order=3)
        assert np.all(np.abs(xs * v) <= limits.vmax)
        assert np.all(np.abs(xss * v * v + xs * a) <= limits.amax)
        assert np.all(np.abs(xsss * v**3 + 3 * xss * v * a + xs * j) <= limits.jmax * 1.001)
        assert vy.entry[0] <= b.V[vy.k0 - 1] and vy.exit[0] <= b.V[vy.k1 + 1]
        assert vy.entry[1] < 0.0 < vy.exit[1]  # braking in, speeding out
        above = max(above, float(np.min(v)) / float(np.min(b.V[vy.k0:vy.k1 + 1])))
    assert above > 1.2  # the slowest point of some valley lies 20 % above its caps


def test_a_refused_valley_is_replanned_without_it_in_the_same_round(dome, monkeypatch):
    """A valley the verification refuses is dropped and the round planned again without
    it (no repair round spent, no budget lowered for it): the plan verifies in round 1
    and keeps the other valleys."""
    _, request = dome
    layouts = (heuristic_planner.COARSE_WIDE,)
    free = HeuristicPlanner(margin=1.0, layouts=layouts).plan(request)
    real = heuristic_planner.failing_segments
    planner = HeuristicPlanner(margin=1.0, layouts=layouts)
    calls = []

    def refuse_first_valley(profile, grid, starts, *args):
        out = real(profile, grid, starts, *args)
        if not calls and planner._fixed is not None and planner._fixed.any():
            out = out.copy()
            out[int(np.argmax(planner._fixed))] = True  # the first valley's first segment
        calls.append(1)
        return out

    monkeypatch.setattr(heuristic_planner, "failing_segments", refuse_first_valley)
    result = planner.plan(request)
    assert result.info["verified"] and result.info["rounds"] == 1
    assert len(calls) == 2
    assert 0 < result.info["valley_segments"] < free.info["valley_segments"]
    without = HeuristicPlanner(margin=1.0, layouts=layouts, valleys=False).plan(request)
    # the other valley kept: between the plan with both and the plan with none
    assert free.profile.duration <= result.profile.duration < without.profile.duration


def test_apex_feeds_above_a_knot_cap_are_skipped_with_the_same_valleys(monkeypatch):
    """A C1 path's knot caps (hard bounds no valley may pass) make most of its cap minima
    valleys whose apex feed lies above the apex cell's bound: `valley._best` skips those
    apex feeds before their span searches. The valleys found are the same as with every
    apex feed searched, with far fewer span searches."""
    import lookahead.planning.heuristic.valley as valley

    p = load_corpus("all", pattern="w-hel-R100-a45-sine-2mm-pchip")[0]
    path = p.path()
    request = PlanRequest(path, p.config.machine.limits.scaled(p.config.planner.margin),
                          PathState(0.0), path.length, dt=p.config.machine.dt)
    planner = HeuristicPlanner(margin=1.0)
    limits = request.limits
    grid, _ = planner._grid(request, request.start, limits)
    assert np.isfinite(grid.c1_cap).any()
    layout = heuristic_planner.COARSE
    vlim = feed_limit(grid, limits, layout.shares, request.feed_cap)
    starts = choose_segments(grid, vlim, layout.band_ratio)
    b = segment_budgets(grid, starts, vlim, limits, layout.shares)
    b, levels = level_budgets(grid, starts, vlim, limits, layout.shares, b, None, None,
                              layout.levels)
    cap = junction_caps(request, grid, starts, b)
    spans = []
    real_span = valley._span

    def counted(*args):
        spans.append(1)
        return real_span(*args)

    monkeypatch.setattr(valley, "_span", counted)

    def search():
        spans.clear()
        got = find_valleys(grid, starts, b, levels, vlim, cap, limits, layout.shares,
                           neighbour_min(b.J), hard=grid.c1_cap)
        return got, len(spans)

    skipped, n_skipped = search()
    monkeypatch.setattr(valley, "_HARD_ROOM", np.inf)  # every apex feed searched
    full, n_full = search()
    assert len(skipped) == len(full)
    for a, c in zip(skipped, full, strict=True):
        assert (a.k0, a.k1, a.entry, a.exit) == (c.k0, c.k1, c.entry, c.exit)
        for x, y in zip((a.phases.duration, a.phases.jerk), (c.phases.duration, c.phases.jerk),
                        strict=True):
            np.testing.assert_array_equal(x, y)
    assert n_skipped < 0.5 * n_full
