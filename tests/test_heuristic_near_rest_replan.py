"""Heuristic replans from the brake to rest at the end of the last plan's window (issue 14):
such a start decelerates hard at a low feed and turns only under more jerk than the first
planning segment's budget at its cruise cap. The planner then caps the segment at the
start feed (which raises its jerk budget); that cap used to cover the whole first segment
(54 mm on the cam-style path), so from v0 = 0.46 mm/s the replan crawled for 123 s. Now
it covers only a short leading cell (`path_limits.lead_length`)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from corpus_windows import FirstWindow, first_window
from lookahead.planning.base import PathState
from lookahead.planning.heuristic.path_limits import lead_length
from lookahead.stream.planners import make_planner

#: samples at the end of the first plan replanned from (its brake to rest), every STEP-th
END_SAMPLES, STEP = 120, 8


@pytest.fixture(scope="module")
def cam_braking() -> FirstWindow:
    return first_window("cam-style-R50-a45-L200")


def test_replans_from_the_brake_to_rest_do_not_crawl(cam_braking):
    """From every sampled state of the brake to rest, the replan takes at most 10 % longer
    than finishing that brake and planning on from rest at its end (a plan the heuristic
    could always make); before the leading cell, 123 s instead of 4.3 from v0 = 0.46 and
    22 % longer from the mid-brake states (v0 ~ 70 mm/s, a0 ~ -1700 mm/s^2)."""
    first = cam_braking
    n, dt = first.samples, first.dt
    at_rest, _ = first.replan(n)
    rest = make_planner("heuristic").plan(replace(
        at_rest, start=PathState(at_rest.start.s))).profile.duration
    slow, braking = [], 0
    for k in range(n - END_SAMPLES, n - 1, STEP):
        request, _ = first.replan(k)
        st = request.start
        if not (st.v > 0.0 and st.a < 0.0):
            continue
        braking += 1
        got = make_planner("heuristic").plan(request).profile.duration
        bound = (n - k) * dt + rest
        if got > 1.1 * bound:
            slow.append((k, round(st.v, 4), round(st.a, 1), round(got, 3), round(bound, 3)))
    assert braking >= 10
    assert not slow, slow


def test_lead_length_covers_the_turn():
    """The leading cell holds the turn of the start's acceleration to 0 and the rise back
    to its feed (their distances, which grow as the jerk falls); none when the start is
    not decelerating."""
    v0, a0, J = 50.0, -1500.0, 20000.0
    t1 = -a0 / J
    turn = v0 * t1 + a0 * t1**2 / 2 + J * t1**3 / 6
    assert lead_length(v0, a0, J) > turn > 0.0
    assert lead_length(v0, a0, J / 2) > lead_length(v0, a0, J)
    assert lead_length(v0, 0.0, J) == 0.0
    assert lead_length(v0, 100.0, J) == 0.0
    assert lead_length(0.0, a0, J) == 0.0
