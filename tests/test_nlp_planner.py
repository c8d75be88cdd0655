"""NLP planner: the rest shape, gradients of the SLSQP problem, profile slicing, and whole
plans judged by the finite-difference checker."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import check_grad

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry.spline_path import fit_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.lp import LPPlanner
from lookahead.planning.nlp import (
    FeedSpline,
    Margins,
    NLPPlanner,
    PointMargins,
    SampledPlan,
    Window,
    WindowProblem,
    knot_vector,
    rest_shape,
    rest_weight,
    velocity_cap,
)
from lookahead.planning.profile_ops import concatenate, slice_profile
from lookahead.sampling import sample_plan

MACHINE = default_config().machine
LIMITS = MACHINE.limits  # the winder's defaults
SCALE = np.asarray(MACHINE.path_scale)
DT = MACHINE.dt


@pytest.fixture(scope="module")
def path():
    """Two winder-like strokes with a turnaround: X 0..600..0 mm, C turning 900 deg."""
    th = np.linspace(0.0, 2.0 * np.pi, 300)
    pts = np.column_stack([300.0 * (1 - np.cos(th)), np.degrees(th) * 2.5 + 20 * np.sin(th)])
    return fit_points(pts, SCALE)


@pytest.fixture(scope="module")
def request_(path):
    return PlanRequest(path, LIMITS, PathState(0.0), path.length)


@pytest.fixture(scope="module")
def start(request_):
    return LPPlanner().plan(request_)


@pytest.fixture(scope="module")
def nlp_result(request_, start):
    class Given:
        name = "given"

        def plan(self, _request):
            return start

    return NLPPlanner(start_planner=Given()).plan(request_)


def test_rest_shape_derivatives_and_onset() -> None:
    x = np.linspace(0.02, 1.3, 400)
    _phi, d1, d2 = rest_shape(x)
    eps = 1e-6
    num1 = (rest_shape(x + eps)[0] - rest_shape(x - eps)[0]) / (2 * eps)
    num2 = (rest_shape(x + eps)[1] - rest_shape(x - eps)[1]) / (2 * eps)
    assert np.allclose(d1, num1, atol=1e-5)
    assert np.allclose(d2, num2, atol=1e-4)
    # C2 join with 1 at x = 1, q ~ (3x)^(4/3) at rest (a constant-jerk start)
    assert np.allclose(rest_shape(np.array([1.0 - 1e-9, 1.0]))[0], 1.0)
    assert abs(rest_shape(np.array([1.0 - 1e-6]))[2][0]) < 1e-4
    small = np.array([1e-6])
    assert rest_shape(small)[0][0] == pytest.approx((3e-6) ** (4 / 3), rel=1e-4)


def test_rest_weight_vanishes_at_both_rest_ends() -> None:
    s = np.array([0.0, 5.0, 50.0, 95.0, 100.0])
    w, _, _ = rest_weight(s, 0.0, 100.0, 10.0, True, True)
    assert w[0] == 0.0 and w[-1] == 0.0 and w[2] == 1.0 and 0 < w[1] < 1


def _problem(path, start, rest0=True, rest1=True, seam=None):
    plan = SampledPlan.of(start, path, LIMITS, DT)
    win = Window(0, plan.s.size - 1, rest0, rest1)
    knots = knot_vector(plan.s, plan.v, plan.v >= 0.985 * plan.vcap, 0.04, 8.0, 300.0)
    spline = FeedSpline(knots, win, 50.0, float(plan.s[0]), float(plan.s[-1]))
    pts = np.linspace(plan.s[0], plan.s[-1], 200)
    margins = PointMargins.uniform(pts, Margins())
    prob = WindowProblem.build(spline, path, LIMITS, margins,
                               lambda x: velocity_cap(path, LIMITS, x), seam, None,
                               np.linspace(plan.s[0], plan.s[-1], 500))
    return prob, plan


def test_gradients_match_finite_differences(path, start) -> None:
    prob, _ = _problem(path, start)
    rng = np.random.default_rng(3)
    z = rng.uniform(0.2, 0.8, prob.spline.n_ctrl)
    assert check_grad(lambda x: prob.time(x)[0], lambda x: prob.time(x)[1], z) < 1e-6 * (
        1 + np.linalg.norm(prob.time(z)[1]))
    jac = prob.ineq_jac(z)
    eps = 1e-7
    for i in rng.choice(z.size, 4, replace=False):
        dz = np.zeros_like(z)
        dz[i] = eps
        num = (prob.ineq(z + dz) - prob.ineq(z - dz)) / (2 * eps)
        assert np.allclose(jac[:, i], num, rtol=1e-4, atol=1e-6 * np.abs(num).max())


def test_jerk_rows_equal_the_chain_rule(path, start) -> None:
    """1 - row = (jerk / (margin jmax))^2 with jerk from numerically differentiated axis
    positions of the motion s(t) given by the spline's q."""
    prob, _ = _problem(path, start)
    z = np.full(prob.spline.n_ctrl, 0.3)
    s_mid = 0.5 * (prob.spline.s0 + prob.spline.s1)
    Q0, Q1, Q2 = prob.spline.operators(np.array([s_mid]), 2)
    c = z * prob.qs
    q, q1, q2 = (Q0 @ c)[0], (Q1 @ c)[0], (Q2 @ c)[0]
    # local motion through s_mid: v = sqrt(q), a = q'/2, j = q'' v / 2
    v, a, j = np.sqrt(q), 0.5 * q1, 0.5 * q2 * np.sqrt(q)
    h = 1e-3
    t = np.arange(-3, 4) * h
    s_t = s_mid + v * t + a * t**2 / 2 + j * t**3 / 6
    x = path.eval_s(s_t, order=0)[0]
    jerk_num = (-x[1] + 2 * x[2] - 2 * x[4] + x[5]) / (2 * h**3)
    d = path.eval_s(np.array([s_mid]), order=3)
    jerk = d[3][0] * v**3 + 3 * d[2][0] * v * a + d[1][0] * j
    assert np.allclose(jerk, jerk_num, rtol=1e-3, atol=1.0)
    margins = Margins()
    expect = 1.0 - (jerk / (margins.jerk * LIMITS.jmax)) ** 2
    rows_at = prob.spline.operators(np.array([s_mid]), 0)[0]
    kappa = prob.qs**1.5 / (margins.jerk * LIMITS.jmax)
    got = [1.0 - (rows_at @ z)[0] * (kappa[k] * (
        d[3][0, k] * (Q0 @ z) + 1.5 * d[2][0, k] * (Q1 @ z) + 0.5 * d[1][0, k] * (Q2 @ z)))[0]
        ** 2 for k in range(2)]
    assert np.allclose(got, expect, rtol=1e-6)


def test_slice_and_concatenate_reproduce_the_profile(start) -> None:
    prof = start.profile
    T = prof.duration
    cuts = [0.0, 0.3137 * T, 0.71 * T, T]
    pieces = [slice_profile(prof, a, b) for a, b in itertools.pairwise(cuts)]
    assert pieces[1].duration == pytest.approx(cuts[2] - cuts[1])
    whole = concatenate(pieces)
    t = np.linspace(0.0, T, 997)
    assert np.allclose(whole.at(t), prof.at(t), rtol=1e-7, atol=1e-6)


def test_nlp_plan_passes_checker_and_beats_or_equals_start(path, start, nlp_result) -> None:
    res = nlp_result
    rep = check_positions(sample_plan(path, res.profile, DT).pos, LIMITS, DT)
    assert rep.ok, rep.first
    assert res.method == "nlp" and res.info["fallback"] is None
    assert res.profile.duration <= start.profile.duration + 1e-9
    assert any(w["status"] == "optimized" for w in res.info["windows"])
    s, v, a, _ = res.profile.at(np.array([0.0, res.profile.duration]))
    assert s[0] == pytest.approx(0.0, abs=1e-9) and s[1] == pytest.approx(path.length)
    assert np.allclose(v, 0.0, atol=1e-9) and np.allclose(a, 0.0, atol=1e-6)


def test_failed_windows_fall_back_to_the_start_plan(request_, start) -> None:
    class Given:
        name = "given"

        def plan(self, _request):
            return start

    res = NLPPlanner(start_planner=Given(), maxiter=1, max_repairs=0).plan(request_)
    rep = check_positions(sample_plan(request_.path, res.profile, DT).pos, LIMITS, DT)
    assert rep.ok
    statuses = [w["status"] for w in res.info["windows"]]
    assert all(st.startswith("fallback") or st == "optimized" for st in statuses)
    assert any(st.startswith("fallback") for st in statuses)
    for w in res.info["windows"]:
        if w["status"].startswith("fallback"):
            assert w["time"] == pytest.approx(w["start_time"])
    assert res.profile.duration <= start.profile.duration + 1e-9
