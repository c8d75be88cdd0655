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
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.planner import FEED_CAP_TOL


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
