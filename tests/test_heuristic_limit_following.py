"""Heuristic planner following the feed-limit curve (issue 14, item 1): rises under
feed-dependent acceleration budgets (`levels`, `rise.rise_levels`), forward rises instead
of zero-acceleration feeds after a restart of the backward scan (near-cusps), segments
split where their constant cap loses time (`split`), the corner check of the planner's own
verification; winding time near the LP on the corpus paths where the heuristic lost most."""

from __future__ import annotations

import numpy as np
import pytest
from bench.corpus import load_corpus
from hypothesis import given, settings
from hypothesis import strategies as st

from lookahead.checker import check_positions
from lookahead.geometry import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile, PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.heuristic.path_limits import BudgetShares, build_grid
from lookahead.planning.heuristic.rise import rise_levels
from lookahead.planning.heuristic.scurve import feed_change_phases
from lookahead.planning.heuristic.split import split_by_loss
from lookahead.planning.heuristic.verify import failing_cells
from lookahead.sampling import sample_plan

DT = 0.001
#: the corpus's XY machine (200 mm/s, 2000 mm/s^2, 40000 mm/s^3 per axis) at its margin
XY = AxisLimits(np.full(2, 196.0), np.full(2, 1960.0), np.full(2, 39200.0))


def _sampled(phases, n: int = 40):
    """(v, a, j) at n points inside every phase of constant jerk."""
    out = []
    for h, j, a, v in zip(phases.duration, phases.jerk, phases.acc, phases.vel, strict=True):
        t = np.linspace(0.0, h, n)
        out.append(np.stack([v + a * t + j * t * t / 2.0, a + j * t, np.full(n, j)]))
    return np.concatenate(out, axis=1)


@settings(max_examples=150, deadline=None)
@given(V=st.floats(1.0, 500.0), f=st.lists(st.floats(0.1, 0.95), min_size=1, max_size=4),
       a_top=st.floats(50.0, 3000.0), gain=st.lists(st.floats(1.0, 3.0), min_size=5,
                                                    max_size=5),
       J=st.floats(1e3, 1e5), v0_frac=st.floats(0.0, 0.9))
def test_rise_levels_keeps_each_level_budget(V, f, a_top, gain, J, v0_frac):
    """The rise never exceeds the budget of the level its feed is in, nor J, nor V; it
    ends at V with acceleration 0, and is never slower than the rise under the top
    level's budget alone."""
    tops = [*sorted({round(x, 6) for x in f}), 1.0]
    tops = [x * V for x in tops]
    # budgets non-increasing with the feed, the top one a_top
    accs = list(np.cumprod(np.array(gain[:len(tops)])[::-1])[::-1] * a_top / gain[-1])
    accs = list(np.minimum.accumulate(accs))
    v0 = v0_frac * tops[0]
    got = rise_levels(0.0, 1e9, v0, 0.0, tops, accs, J)
    assert got is not None
    phases = got[0]
    moving = phases.duration[:-1]  # the last phase is the cruise at V after the rise
    v, a, j = _sampled(phases)
    level = np.searchsorted(np.array(tops) * (1 + 1e-9), v)
    budget = np.array(accs)[np.minimum(level, len(accs) - 1)]
    assert np.all(a <= budget * (1 + 1e-7) + 1e-9)
    assert np.all(np.abs(j) <= J * (1 + 1e-12))
    assert np.all(v <= V * (1 + 1e-9))
    assert abs(got[1] - V) <= 1e-7 * V and abs(got[2]) <= 1e-9 * a_top
    plain = feed_change_phases(0.0, v0, 0.0, V, accs[-1], J)
    assert np.sum(moving) <= np.sum(plain.duration) * (1 + 1e-9)


def test_rise_levels_from_a_hair_below_the_top_stays_there():
    """Cause (a jump of 10 mm/s in the feed, jerk 93x the limit, near-zero-feed test): a
    start 4e-14 below the top with a = 6e-14 met the final ramp's line, 2 J (V - v), by
    rounding 0: it was taken for a start above a level's hold and 'eased' down to a hold
    10 mm/s lower. The rise must start where it is and stay at the top."""
    tops = [97.43118920798044, 158.32568246296822, 207.04127706695843, 243.5779730199511]
    accs = [1147.9890883027656, 706.4548235709326, 540.2301592013014, 459.19563532110624]
    v0 = 243.57797301995106
    got = rise_levels(220.3111376538625, 14.843408994431599, v0, 5.684341886080802e-14, tops,
                      accs, 10974.541370327068)
    assert got is not None
    assert np.max(np.abs(got[0].vel - v0)) <= 1e-9 * v0
    assert abs(got[1] - v0) <= 1e-9 * v0


def test_split_by_loss_cuts_a_long_segment_at_its_low_start():
    """A 1000-cell stroke whose first 50 cells sit 20 % lower is cut where the limit
    rises (its cap there had cost 19 % of its time); a flat one stays whole."""
    edges = np.linspace(0.0, 1000.0, 1001)
    vlim = np.full(1000, 1200.0)
    vlim[:50] = 1000.0
    starts = np.array([0, 1000])
    got = split_by_loss(edges, vlim, starts, 0.02, 0.05, 1.05)
    assert got.tolist() == [0, 50, 1000]
    assert split_by_loss(edges, np.full(1000, 1200.0), starts, 0.02, 0.05, 1.05).tolist() \
        == [0, 1000]
    # a loss below the absolute threshold is kept (a short stroke: few samples lost)
    assert split_by_loss(edges * 1e-3, vlim, starts, 0.02, 0.05, 1.05).tolist() == [0, 1000]


def test_verification_flags_a_feed_kept_through_a_corner():
    """A crawl (1e-3 mm/s) through a pchip cusp breaks no axis term at the grid points
    (they stay a quarter cell away from the corner) but the machine must stop there: the
    cells before the corner fail, the rest pass."""
    path = fit_points(np.array([[0.0, 0.0], [10.0, 3.0], [0.0, 1.0]]), np.ones(2), "pchip")
    assert path.corners_s().size == 1
    grid = build_grid(path, 0.0, path.length, DT, XY, BudgetShares())
    v = 1e-3
    from scipy.interpolate import PPoly

    profile = FeedProfile(PPoly(np.array([[0.0], [0.0], [v], [0.0]]),
                                np.array([0.0, path.length / v])))
    bad = failing_cells(profile, grid, XY)
    assert np.array_equal(np.nonzero(bad)[0], np.nonzero(grid.corner_after)[0])


def _corpus(name):
    return next(p for p in load_corpus("all") if p.name == name)


def _request(p):
    path = p.path()
    limits = p.config.machine.limits.scaled(p.config.planner.margin)
    return path, PlanRequest(path, limits, PathState(0.0), path.length,
                             feed_cap=p.geometry().feed_cap(), dt=p.config.machine.dt)


@pytest.mark.parametrize("name, within", [("n-circle-R30", 1.10),
                                          ("c-cycloid-near-cusp-a0p995", 1.20)])
def test_corpus_paths_wind_near_the_lp(name, within):
    """On the circle under per-axis limits and the near-cusp cycloid (where the heuristic
    took 1.22x and 1.33x the LP's time) the whole-job plan is within `within` of the
    LP's winding time and passes the checker at the full limits. (The cycloid's bound
    was 1.10 against the LP before issue 13's jerk-change and grid fix, which made the
    LP 2.153 -> 1.936 s; the heuristic's 2.260 s is 1.17x that.)"""
    from lookahead.planning.lp import LPPlanner

    p = _corpus(name)
    path, request = _request(p)
    heuristic = HeuristicPlanner(margin=1.0).plan(request)
    lp = LPPlanner().plan(request)
    assert heuristic.profile.duration <= within * lp.profile.duration, (
        heuristic.profile.duration, lp.profile.duration)
    m = p.config.machine
    report = check_positions(sample_plan(path, heuristic.profile, m.dt).pos, m.limits, m.dt)
    assert report.ok, report.first


def test_circle_feed_follows_the_lp_feed():
    """Between the rise from rest and the stop (the middle 70 % of the circle) the feed
    stays within 12 % of the LP's feed at the same s: the plan follows the wavy limit
    curve instead of cruising under its lowest point."""
    from lookahead.planning.lp import LPPlanner

    p = _corpus("n-circle-R30")
    path, request = _request(p)
    h = HeuristicPlanner(margin=1.0).plan(request).profile
    lp = LPPlanner().plan(request).profile
    s = np.linspace(0.15, 0.85, 200) * path.length

    def feed(profile):
        t = np.linspace(0.0, profile.duration, 20_000)
        pos, vel = profile.at(t)[:2]
        return np.interp(s, pos, vel)

    ratio = feed(h) / feed(lp)
    assert np.min(ratio) >= 0.88, np.min(ratio)


def _circle(radius: float) -> np.ndarray:
    th = np.linspace(0.0, 2.0 * np.pi, max(40, int(2.0 * np.pi * radius / 0.5)))
    return radius * np.column_stack([np.cos(th), np.sin(th)])


def _cycloid(a: float, scale: float) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * 2.0 * np.pi, 1500)
    return scale * np.column_stack([t - a * np.sin(t), 1.0 - a * np.cos(t)])


@settings(max_examples=4, deadline=None)
@given(radius=st.floats(3.0, 80.0))
def test_circles_pass_the_checker(radius):
    _plan_and_check(fit_points(_circle(radius), np.ones(2), "cubic"))


@settings(max_examples=4, deadline=None)
@given(a=st.floats(0.9, 0.999), scale=st.floats(4.0, 20.0))
def test_near_cusp_cycloids_pass_the_checker(a, scale):
    _plan_and_check(fit_points(_cycloid(a, scale), np.ones(2), "cubic"))


def _plan_and_check(path):
    request = PlanRequest(path, XY, PathState(0.0), path.length, dt=DT)
    result = HeuristicPlanner(margin=1.0).plan(request)
    report = check_positions(sample_plan(path, result.profile, DT).pos,
                             AxisLimits(XY.vmax / 0.98, XY.amax / 0.98, XY.jmax / 0.98), DT)
    assert report.ok, report.first
