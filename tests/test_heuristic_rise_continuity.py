"""The feed-level rise (`rise.rise_levels`) is one continuous motion: each phase starts
at the feed and acceleration the one before ends with. A start a few 1e-13 below a level's
acceleration ceiling was neither "climbing" (outside the climb's tolerance) nor "on the
ceiling" (a stricter relative test), so the hold was skipped and the ramp down claimed the
hold's feed gain: a feed jump of 22.6 mm/s inside one planned segment, 9.9e6 mm/s^3 in the
checker on a circle of radius 21.16 (found by test_circles_pass_the_checker)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lookahead.planning.heuristic.rise import rise_levels


def _gaps(phases) -> tuple[float, float]:
    """Largest jump of feed and of acceleration between consecutive phases."""
    h, j, a, v = phases.duration, phases.jerk, phases.acc, phases.vel
    v_end = v + a * h + j * h * h / 2.0
    a_end = a + j * h
    if h.size < 2:
        return 0.0, 0.0
    return float(np.max(np.abs(v_end[:-1] - v[1:]))), float(np.max(np.abs(a_end[:-1] - a[1:])))


def test_start_a_hair_below_a_ceiling():
    """The rise the circle's plan made (its start 5.5e-13 below the level's ceiling)."""
    tops = [85.71620145802372, 139.28882736928855, 182.14692809830038, 214.2905036450593]
    accs = [1190.3837477483044, 732.5438447681872, 560.1805871756727, 336.1570336315155]
    got = rise_levels(0.0, 2.5810281393150944, 154.0590004438965, 560.1805871753648, tops,
                      accs, 18416.22712714018)
    assert got is not None
    dv, da = _gaps(got[0])
    assert dv <= 1e-9 * tops[-1], dv
    assert da <= 1e-9 * accs[0], da


@settings(max_examples=60, deadline=None)
@given(level=st.integers(0, 2), below=st.floats(0.0, 1e-10), where=st.floats(0.0, 0.95),
       length=st.floats(0.1, 50.0))
def test_starts_at_a_ceiling_rise_continuously(level, below, where, length):
    """From any feed within a level, at (up to 1e-10 relative below) its acceleration
    ceiling, the rise is continuous in feed and acceleration."""
    tops = [80.0, 140.0, 180.0, 215.0]
    accs = [1200.0, 730.0, 560.0, 340.0]
    J = 18000.0
    lo = tops[level - 1] if level else 0.0
    v0 = lo + where * (tops[level] - lo)
    a0 = accs[level] * (1.0 - below)
    got = rise_levels(0.0, length, v0, a0, tops, accs, J)
    if got is None:
        return  # outside what the level rise covers (the caller uses one budget)
    dv, da = _gaps(got[0])
    assert dv <= 1e-9 * tops[-1], dv
    assert da <= 1e-9 * accs[0], da
