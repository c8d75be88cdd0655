"""The LP keeps a segment's feed cap between its nodes, not only at them.

q <= cap^2 holds at the nodes; the quintic reconstruction between them overshot the cap
by up to 3.4 % (the 20k-line program at F6000 = 100 mm/s, accelerating out of a
turnaround lock), unseen by the checker, which judges the axis limits only. The LP's own
verification now counts the feed over its cap (beyond `FEED_CAP_TOL`), and a repair
tightens the cap where it was exceeded.
"""

from __future__ import annotations

import numpy as np

from cam_paths import lock_program
from lookahead.checker import check_positions
from lookahead.geometry.spline_path import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedCap, PathState, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.grid import with_breaks
from lookahead.planning.lp.planner import FEED_CAP_TOL
from lookahead.sampling import sample_plan


def test_replans_accelerating_out_of_a_lock_keep_the_feed_cap() -> None:
    """Cold replans from the LP's own acceleration out of a turnaround lock (states 8 ms
    apart, path acceleration > 200 mm/s^2) under the program's 100 mm/s cap: the feed
    rose to 103.7 mm/s before (4 of 17 states 4 ms apart over 100.5)."""
    prog = lock_program()
    path, cap, s_lock, m = prog.path, prog.cap, prog.s_lock, prog.config.machine
    lim = m.limits.scaled(prog.config.planner.margin)
    first = PlanRequest(path, lim, PathState(s_lock - 150.0), s_lock + 150.0, feed_cap=cap,
                        dt=m.dt)
    profile = LPPlanner().plan(first).profile
    ts = np.arange(0.0, profile.duration, 0.008)
    s_t, _, a_t = profile.at(ts)[:3]
    rising = ts[(s_t > s_lock) & (s_t < s_lock + 40.0) & (a_t > 200.0)]
    assert rising.size >= 5
    top = 0.0
    for t in rising:
        ss, v, a = (float(x) for x in profile.at(np.array([t]))[:3, 0])
        res = LPPlanner().plan(PlanRequest(path, lim, PathState(ss, v, a), ss + 200.0,
                                           feed_cap=cap, dt=m.dt))
        feed = res.profile.at(np.arange(0.0, res.profile.duration, m.dt / 4))[1]
        top = max(top, float(feed.max()))
    assert 99.0 <= top <= 100.0 * (1.0 + FEED_CAP_TOL) + 1e-9


def test_node_caps_take_the_lower_cap_of_the_intervals_beside_them() -> None:
    """`FeedCap.at_nodes`: a node before a drop or after a rise of the cap bounds a feed
    the interval beside it carries into the lower cap, so it gets that cap; a node on a
    break gets the smaller side; nodes inside one cap keep it."""
    cap = FeedCap(np.array([0.0, 10.0, 20.0, 21.0, 40.0]), np.array([50.0, 5.0, 30.0, 80.0]))
    nodes = np.array([0.0, 4.0, 8.0, 12.0, 16.0, 20.0, 24.0, 28.0])
    assert np.array_equal(cap.at(nodes), [50, 50, 50, 5, 5, 30, 80, 80])
    # 8 -> 12 crosses the drop to 5; 16 -> 20 ends on the rise, 20 -> 24 crosses 30 and 80
    assert np.array_equal(cap.at_nodes(nodes), [50, 50, 5, 5, 5, 5, 30, 80])
    on_breaks = np.array([0.0, 10.0, 20.0, 21.0, 40.0])
    assert np.array_equal(cap.at_nodes(on_breaks), [50, 5, 5, 30, 80])


def test_breaks_become_nodes_and_rest_nodes_stay() -> None:
    """`with_breaks`: every break strictly inside gets a node (a near node moves onto
    it, otherwise one is inserted), the nodes stay increasing, rest nodes and the nodes
    up to `first` keep their place, and the rest indices follow the insertions."""
    nodes = np.linspace(0.0, 10.0, 11)
    stops = np.array([5])
    breaks = np.array([-1.0, 1.5, 2.1, 5.05, 7.0, 10.0, 12.0])
    s, idx = with_breaks(nodes, stops, breaks)
    assert np.all(np.diff(s) > 0)
    assert s[idx[0]] == 5.0
    for b in (1.5, 2.1, 7.0):
        assert b in s
    assert 5.05 not in s  # beside the rest node: left to the node caps
    assert s[0] == 0.0 and s[-1] == 10.0
    s2, idx2 = with_breaks(nodes, stops, np.array([1.5, 7.0]), first=3)
    assert 1.5 not in s2 and 7.0 in s2
    assert np.array_equal(s2[:4], nodes[:4]) and s2[idx2[0]] == 5.0


def test_a_feed_that_drops_and_rises_is_planned_without_a_velocity_repair() -> None:
    """A straight line at 80 mm/s, 5 mm/s over 10 mm from s = 103.3, then 80 again (the
    breaks between grid nodes): the feed stays under the cap at every sample and no
    repair round is spent on it. Before the breaks were nodes, the node before the drop
    kept the feed at 80 into the 5 mm/s stretch (the pocketing program: 18 % over)."""
    limits = AxisLimits(np.array([100.0, 100.0]), np.array([2000.0, 2000.0]),
                        np.array([40000.0, 40000.0]))
    pts = np.column_stack([np.linspace(0.0, 300.0, 61), np.zeros(61)])
    path = fit_points(pts, np.ones(2))
    cap = FeedCap(np.array([0.0, 103.3, 113.3, path.length]), np.array([80.0, 5.0, 80.0]))
    res = LPPlanner().plan(PlanRequest(path, limits, PathState(0.0), path.length,
                                       feed_cap=cap, dt=0.001))
    assert res.info["repairs"] == 0
    t = np.arange(0.0, res.profile.duration, 0.0005)
    s, v = res.profile.at(t)[:2]
    assert np.all(v <= cap.at(s) * (1.0 + FEED_CAP_TOL) + 1e-9)
    slow = (s > 103.3) & (s < 113.3)
    assert np.max(v[slow]) > 4.9  # the slow stretch at its cap, not below it


def test_the_pocketing_program_plans_as_one_job(monkeypatch) -> None:
    """The corpus's 3-axis pocketing G-code (F300 plunges, F1200 passes, F4800 finish,
    ~4300 LP nodes) as one whole-job LP: its repairs moved excesses of 0.2-13 % from
    place to place and the plan gave up after 8 rounds (then its retry stalled: "the jerk
    LP has no solution"); a round that makes progress (a new place, the smallest excess
    so far) now does not count (`REPAIRS_PER_BUDGET`). The plan passes the
    finite-difference checker."""
    from bench.corpus import load_corpus

    p = next(c for c in load_corpus("all") if c.name == "cnc-feed-mill-pocket-mixed")
    path, m = p.path(), p.config.machine
    req = PlanRequest(path, m.limits.scaled(p.config.planner.margin), PathState(0.0),
                      path.length, feed_cap=p.geometry().feed_cap(), dt=m.dt)
    # the distance objective, its pinned nodes linearized as before stop 43 (no extra
    # passes on LPs over 4000 nodes): its plan needs more rounds than the budget, the case
    # under test (the default, time-weighted objective needs 6; with the extra passes 5),
    # with every repair round global (local rounds, `lp.local_repair`, need 4) and stalls
    # lifted by `_unstall` alone (with `stall_recap` it needs 6)
    from lookahead.planning.lp import planner as lp_planner

    monkeypatch.setattr(lp_planner, "RELINEARIZE_MAX_NODES", 4000)
    res = LPPlanner(objective="distance", local_repair=0, stall_recap=False).plan(req)
    smp = sample_plan(path, res.profile, m.dt)
    assert check_positions(smp.pos, m.limits, m.dt).violations == 0
    assert res.info["repairs"] > LPPlanner().max_repairs  # more than the old budget
