"""Replans from states on the planner's own committed plan (bench/replan_continuity.py):
every replan of the service starts on its last plan, including the braking into that
plan's window end, where a replan is most often needed (a late segment, a failed replan)."""

from __future__ import annotations

import numpy as np
import pytest
from bench.corpus import load_corpus
from bench.replan_continuity import run_path, states_on

from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner


def test_states_on_cover_the_braking_end():
    """The sampled states include the last END_SHARE of the plan (its braking to rest)."""
    geo = load_corpus("fast", pattern="n-circle-R30")[0]
    path = geo.path()
    lim = geo.config.machine.limits.scaled(0.98)
    prof = HeuristicPlanner(margin=1.0).plan(
        PlanRequest(path, lim, PathState(0.0), path.length, dt=geo.config.machine.dt)).profile
    got = states_on(prof, 20, np.random.default_rng(3))
    t = np.array([ti for ti, _ in got])
    assert t.size == 25 and np.all(np.diff(t) >= 0)
    assert np.sum(t >= 0.98 * prof.duration) >= 5
    ends = [st for ti, st in got if ti >= 0.98 * prof.duration]
    assert all(st.a <= 1e-9 for st in ends[:-1])  # braking, not accelerating


@pytest.mark.parametrize("name", ["w-issue-tube1450-R100-a45-sine-2mm", "c-rand2-xy-500pts",
                                  "n-circle-R30"])
def test_heuristic_replans_from_any_state_of_its_plan(name):
    """0 refused replans from states of the heuristic's own first window (on the fast
    corpus 0 of 518 failed; the long CAM program's 3 failed replans were such states)."""
    p = load_corpus("fast", pattern=name)[0]
    r = run_path(p, "heuristic", 8, seed=5)
    assert r["replans"] >= 8
    assert r["failures"] == 0, r["examples"]


# used to refuse the replans from the braking into the window's end (18 of 518 on the
# fast corpus, all for jerk: the first quintic from a low-feed braking state reversed);
# fixed by the closed-form release of such a start (`lp.release`)
@pytest.mark.parametrize("name", ["w-hoop-R40-band8-2mm"])
def test_lp_replans_from_any_state_of_its_plan(name):
    """0 refused LP replans from states of its own first window, the braking into its end
    included (the fast corpus: 0 of 700). 16 states: 4 in the last 2 % of the plan, of
    which 2 were refused before the fix."""
    p = load_corpus("fast", pattern=name)[0]
    r = run_path(p, "lp", 16, seed=5)
    assert r["replans"] >= 16
    assert r["failures"] == 0, r["examples"]
