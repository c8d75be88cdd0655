"""Feeds a jerk-limited motion cannot reach within a distance: a cheap test run before a
Ruckig state-to-state segment (`scurve.SCurveSolver.segment`) that it would refuse.

Units: path units (mm) and seconds. A motion along s starts at feed v0 > 0 with
acceleration a0, |a| <= A, |j| <= J (A >= |a0|). Over its first distance L:
- no motion ends faster than sqrt(v0^2 + 2 A L) (d(v^2)/ds = 2 a <= 2 A). The jerk-limited
  rise a(t) = min(a0 + J t, A) is no bound in distance: a motion that brakes first
  reaches L later, with more time to build up acceleration, and can pass it faster
  (Ruckig found one 1.8 % above that rise);
- no motion ends below both v0 and the feed of the brake a(t) = max(a0 - J t, -A) at L
  (while the brake's feed stays > 0): the brake has the lowest acceleration, feed and
  position at every time, so any other motion passes L sooner, at a feed no lower than
  the brake's at that time, and the brake's feed rises (while a > 0), then falls.
A target feed above the first or below the second, beyond a tolerance, is out of reach;
anything else is left to Ruckig. Played backwards (from (v1, -a1) to v0), a motion obeys
the same limits, so the same test bounds where it can come from.

Why: on the fast corpus 50-75 % of the heuristic's Ruckig segments were refused (the
backward scan's restarts try to land rises on states out of reach, up to 15 times per
failed landing), at ~19 us a refusal (Python round trip and exception); this test costs
~1-2 us. It refuses only what Ruckig refuses, so plans stay bit-identical.
"""

from __future__ import annotations

import math

#: relative feed tolerance of the test (of the largest of v0, v1 and the cap V): it only
#: refuses where the target lies clearly outside the extremes (rounding of the cut and of
#: Ruckig's own tolerances stay orders of magnitude below)
REACH_TOL = 1e-5


def surely_refused(L: float, v0: float, a0: float, v1: float, a1: float, V: float,
                   A: float, J: float) -> bool:
    """True where Ruckig surely finds no motion over L from (v0, a0) to (v1, a1) under
    0 <= v, the cap V, |a| <= A (>= |a0|, |a1|), |j| <= J: a target feed above V (Ruckig
    refuses it by any margin), or v1 out of reach forwards, or v0 out of reach of the
    motion played backwards (from (v1, -a1), the same limits). False: Ruckig decides."""
    return v1 > V * (1.0 + 1e-9) or out_of_reach(L, v0, a0, v1, V, A, J) \
        or out_of_reach(L, v1, -a1, v0, V, A, J)


def out_of_reach(L: float, v0: float, a0: float, v1: float, V: float, A: float,
                 J: float) -> bool:
    """True if feed v1 is surely out of reach after distance L from (v0, a0) under
    |a| <= A, |j| <= J (V: the cruise cap, only for the tolerance's scale); False where
    the test cannot tell (Ruckig decides)."""
    if not (L > 0.0 and v0 > 0.0 and A > 0.0 and J > 0.0 and abs(a0) <= A):
        return False
    tol = REACH_TOL * max(v0, v1, V)
    if v1 > v0:
        return v1 > math.sqrt(v0 * v0 + 2.0 * A * L) + tol
    if v1 < v0:
        dn = _brake_feed(L, v0, a0, A, J)
        return dn is not None and v1 < dn - tol
    return False


def cubic_time_at(goal: float, v: float, a: float, j: float, hi: float, t: float,
                  iterations: int, tol: float) -> float:
    """The time in [0, hi] at which s(t) = v t + a t^2 / 2 + j t^3 / 6 (increasing there,
    s(hi) >= goal) reaches goal: Newton steps from t kept inside the bracket (bisection
    where a step leaves it), until a step is below tol or after `iterations` steps.
    Hand-written for the scans' inner loops (`scurve.cut_lists` uses it too): measured on
    one brake, 2.3 us a root against 14.6 us for scipy's brentq to the same tolerance."""
    lo = 0.0
    for _ in range(iterations):
        f = ((j / 6.0 * t + a / 2.0) * t + v) * t - goal
        if f < 0.0:
            lo = t
        else:
            hi = t
        fp = (j / 2.0 * t + a) * t + v
        t_new = t - f / fp if fp > 0.0 else 0.5 * (lo + hi)
        if not lo <= t_new <= hi:
            t_new = 0.5 * (lo + hi)
        if abs(t_new - t) <= tol:
            return t_new
        t = t_new
    return t


def _time_at(L: float, v: float, a: float, j: float, hi: float) -> float:
    """`cubic_time_at` from the bracket's end hi (the brake's end or its jerk phase's)."""
    return cubic_time_at(L, v, a, j, hi, hi, 40, 1e-14 * hi)


def _brake_feed(L: float, v0: float, a0: float, A: float, J: float) -> float | None:
    """Feed of the brake a(t) = max(a0 - J t, -A) from (v0 > 0, a0) where it passes L;
    None if its feed reaches 0 before (from rest on, any feed is reachable)."""
    t1 = (a0 + A) / J  # the end of the jerk phase
    # where the feed v0 + a0 t - J t^2 / 2 would reach 0 on the jerk phase
    t_stop = (a0 + math.sqrt(a0 * a0 + 2.0 * J * v0)) / J
    if t_stop <= t1:  # the feed reaches 0 on the jerk phase
        d_stop = ((-J / 6.0 * t_stop + a0 / 2.0) * t_stop + v0) * t_stop
        if not d_stop > L:
            return None
        t = _time_at(L, v0, a0, -J, t_stop)
        return v0 + a0 * t - J * t * t / 2.0
    d1 = ((-J / 6.0 * t1 + a0 / 2.0) * t1 + v0) * t1
    if d1 >= L:
        t = _time_at(L, v0, a0, -J, t1)
        return v0 + a0 * t - J * t * t / 2.0
    v1 = v0 + a0 * t1 - J * t1 * t1 / 2.0
    rest = v1 * v1 - 2.0 * A * (L - d1)
    return math.sqrt(rest) if rest > 0.0 else None
