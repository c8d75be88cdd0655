"""The LP's envelopes into and out of rest follow the tangent where the rest is
(`LPPlanner._envelope`, `lp.envelope.rest_envelope`), not the worst tangent of the path,
where the curvature terms near the rest stay small.

Near a rest the curvature terms vanish with the feed, so the axis limits bound the path
acceleration and jerk through the tangent alone: min_k amax_k / |x'_k|. The envelopes
used `path_limits` (any axis may carry the whole tangent): on the winder that is X's
2000 mm/s^2 even where C carries 95 % of the tangent and allows 5244. A stroke from rest
to rest then accelerated at 38 % of what its axes allowed (w-hel-R25-a30-cycloid-0p2mm:
the whole-job LP 12.8 % slower than the fine-grid reference, issue 13)."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import plan_rest_to_rest
from lookahead.planning.lp import LPPlanner, envelope
from lookahead.planning.lp.envelope import (
    REST_CURVATURE_SHARE,
    local_rest_q,
    lowered_rest_envelope,
    path_limits,
    reachable_q,
    rest_envelope,
    tangent_limits,
)
from lookahead.planning.lp.rows import GridGeometry, Tightening
from lookahead.sampling import sample_plan
from motion_bounds import rest_to_rest_duration


@pytest.mark.parametrize("solver", ["highs", "osqp"])
def test_a_stroke_along_c_accelerates_at_its_own_tangents_limits(solver: str) -> None:
    machine = default_config().machine
    # X 300 mm while C turns 10 times: C carries 95 % of the tangent (path units)
    c = np.linspace(0.0, 3600.0, 41)
    path = fit_points(np.column_stack([300.0 * c / 3600.0, c]),
                      np.asarray(machine.path_scale), "cubic")
    limits = machine.limits.scaled(0.98)
    tangent = np.abs(path.eval_s(np.array([0.0]), order=1)[1, 0])
    a_tangent, _ = tangent_limits(tangent, limits)
    a_worst, _ = path_limits(path, limits)
    assert a_tangent > 2.5 * a_worst  # 5139 against 1960 mm/s^2

    result = LPPlanner(solver=solver).plan(PlanRequest(path, limits, PathState(0.0),
                                                       path.length))
    smp = sample_plan(path, result.profile, machine.dt)
    assert check_positions(smp.pos, machine.limits, machine.dt).violations == 0
    t = np.arange(0.0, result.profile.duration, machine.dt)
    accel = result.profile.at(t)[2]
    # before: the envelopes held the path acceleration to a_worst (peak 1950 mm/s^2)
    assert np.max(accel) > 2.0 * a_worst
    assert np.min(accel) < -2.0 * a_worst
    # Ruckig's time-synchronized move (a lower bound for the straight one): before,
    # 5.950 s against 5.442 (1.093x)
    best = rest_to_rest_duration(np.array([300.0, 3600.0]), limits)
    assert result.profile.duration < 1.05 * best


def test_a_rest_in_a_bend_keeps_the_conservative_envelope() -> None:
    """`rest_envelope` follows the tangent where the curvature terms at its feeds stay
    small (a straight stroke), and gives way (None) where they do not (a rest on a circle
    of 30 mm, whose centripetal term reaches amax at 212 mm/s)."""
    lim = AxisLimits(vmax=np.array([150.0, 150.0]), amax=np.array([1500.0, 1500.0]),
                     jmax=np.array([20000.0, 20000.0]))
    ones = np.ones(2)
    line = fit_points(np.column_stack([np.linspace(0, 100, 21), np.linspace(0, 30, 21)]),
                      ones, "cubic")
    theta = np.linspace(0.0, np.pi, 61)
    arc = fit_points(30.0 * np.column_stack([np.cos(theta), np.sin(theta)]), ones, "cubic")
    for path, straight in ((line, True), (arc, False)):
        geo = GridGeometry.sample(path, np.linspace(0.0, path.length, 201))
        scale = np.full(geo.s.size, 0.9)
        q_top = float(np.max(lim.vmax)) ** 2
        env = rest_envelope(geo.s, 0.0, geo.d1, geo.d2, geo.d3, lim, scale, scale, q_top)
        if straight:
            assert env is not None
            assert env == pytest.approx(local_rest_q(geo.s, 0.0, geo.d1, lim, scale, scale))
            # an undefined tangent (a pchip knot where the fit stops in every axis) makes
            # the bound NaN beyond it: the conservative envelope, never NaN bounds
            d1 = geo.d1.copy()
            d1[100] = np.nan
            assert rest_envelope(geo.s, 0.0, d1, geo.d2, geo.d3, lim, scale, scale,
                                 q_top) is None
        else:
            assert env is None
            # the coupling 3 |x_ss| v A (A <= 1500 here) takes the share at v >= share jmax
            # R / (3 * 1500): a bound that stops below it follows the tangent on the circle
            v = REST_CURVATURE_SHARE * 20000.0 * 30.0 / (3.0 * 1500.0)
            near = rest_envelope(geo.s, 0.0, geo.d1, geo.d2, geo.d3, lim, scale, scale,
                                 (0.5 * v) ** 2)
            assert near is not None


def _arc_with_a_slow_axis(radius: float, turns: float = 0.75) -> tuple:
    """`turns` (default three quarters) of a circle of `radius` in X/Y, from rest to rest,
    while Z climbs 2 % of the path: Z's limits are 1/200 of X's and Y's, so the path-level
    envelope limits (any axis may carry the whole tangent) are Z's, 50 mm/s^2 and 1000
    mm/s^3."""
    theta = np.linspace(0.0, 2.0 * np.pi * turns, round(80 * turns) + 1)
    points = np.column_stack([radius * np.sin(theta), radius * (1.0 - np.cos(theta)),
                              0.02 * radius * theta])
    path = fit_points(points, np.ones(3), "cubic")
    lim = AxisLimits(vmax=np.array([500.0, 500.0, 5.0]), amax=np.array([1e4, 1e4, 50.0]),
                     jmax=np.array([2e5, 2e5, 1000.0]))
    return path, lim


def test_a_rest_in_a_moderate_bend_follows_its_tangent_lowered_by_the_curvature(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A rest in a bend where the curvature terms at the tangent-only bound's feeds take
    more than REST_CURVATURE_SHARE (R 20 mm: the centripetal term reaches 0.31 amax at
    Z's feed limit 250 mm/s): `lowered_rest_envelope`, the bound with each node's limits
    lowered by those terms, not the path-level envelope of the slow axis. Before, the
    whole-job LP started and stopped at Z's 50 mm/s^2: 2.87 s against 0.58 s
    (c-rand6-scales-raw's rests in bends, issue 13)."""
    path, lim = _arc_with_a_slow_axis(20.0)
    geo = GridGeometry.sample(path, np.linspace(0.0, path.length, 301))
    scale = np.full(geo.s.size, 0.7)
    q_top = 250.0**2
    args = (geo.s, 0.0, geo.d1, geo.d2, geo.d3, lim, scale, scale, q_top)
    assert rest_envelope(*args) is None  # the bend takes more than the share
    a_path, j_path = path_limits(path, lim)
    conservative = reachable_q(geo.s, 0.0, 0.0, 0.7 * j_path, a_path)
    lowered = lowered_rest_envelope(*args, conservative)
    assert lowered is not None
    tangent_only = local_rest_q(geo.s, 0.0, geo.d1, lim, scale, scale)
    near = tangent_only < q_top
    assert np.all(lowered <= tangent_only * (1.0 + 1e-12))
    assert np.any(lowered[near] < tangent_only[near])  # lowered where the bend is
    assert np.all(lowered[near] >= conservative[near])
    # where it would not lift the conservative envelope CURVED_REST_LIFT times: None
    assert lowered_rest_envelope(*args, lowered / (0.5 * envelope.CURVED_REST_LIFT)) is None

    def plan() -> tuple[float, int]:
        request = PlanRequest(path, lim.scaled(0.98), PathState(0.0), path.length)
        result = LPPlanner(rest_splice=False).plan(request)
        report = check_positions(sample_plan(path, result.profile, 0.001).pos, lim, 0.001)
        return result.profile.duration, report.violations

    duration, violations = plan()
    assert violations == 0
    # the transient planner's whole job (its S-curves follow the tangent): 0.571 s
    heuristic = plan_rest_to_rest(path, lim.scaled(0.98)).profile.duration
    assert duration < 1.05 * heuristic

    monkeypatch.setattr(envelope, "CURVED_REST_FLOOR", 2.0)  # no share is ever left
    assert lowered_rest_envelope(*args, conservative) is None
    before, violations = plan()
    assert violations == 0
    assert duration < 0.5 * before


def test_a_rest_in_a_tight_bend_keeps_the_conservative_envelope_still() -> None:
    """Where the lowered bound would leave less than CURVED_REST_FLOOR of the tangent's
    limits (R 2 mm: the coupling alone exceeds Y's jerk limit at Z's feed limit), None."""
    path, lim = _arc_with_a_slow_axis(2.0)
    geo = GridGeometry.sample(path, np.linspace(0.0, path.length, 301))
    scale = np.full(geo.s.size, 0.7)
    args = (geo.s, 0.0, geo.d1, geo.d2, geo.d3, lim, scale, scale, 250.0**2)
    assert rest_envelope(*args) is None
    assert lowered_rest_envelope(*args, np.zeros(geo.s.size)) is None


def test_a_windows_provisional_end_in_a_bend_keeps_the_conservative_envelope() -> None:
    """The lowered envelope is for rests: the path's end, not a window's provisional end
    inside the path (there the windows braked later and their replans lost: engine-lp
    cam-style-R50 +1.0 %). The same bend ends a whole path (lowered) and a window of a
    path that goes on (conservative): 2 mm before the end the bound differs > 2x."""
    whole, lim = _arc_with_a_slow_axis(20.0)
    longer, _ = _arc_with_a_slow_axis(20.0, turns=1.5)
    planner = LPPlanner()
    ends = []
    for path in (whole, longer):
        s_end = whole.length
        geo = GridGeometry.sample(path, np.linspace(0.0, s_end, 301))
        request = PlanRequest(path, lim, PathState(0.0), s_end)
        tight = Tightening.uniform(geo.s.size, *planner.margins)
        env = planner._envelope(request, geo, tight, np.array([], dtype=int))
        ends.append(float(np.interp(s_end - 2.0, geo.s, env)))
    assert longer.length > 1.9 * whole.length  # the window ends inside the longer path
    assert ends[0] > 2.0 * ends[1]
