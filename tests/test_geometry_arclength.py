"""Arc length on paths that wander back and forth (near-cusps, where ds/du nearly vanishes
inside a knot interval) and through exact cusps: s(u) and u(s) stay accurate and smooth,
so x(u(s)) sampled at 1 ms of a constant feed is as smooth as the true x(s)."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest
from scipy.integrate import quad

from lookahead.geometry import fit_points
from lookahead.geometry.base import arc_length_derivatives

SCALE = np.array([1.0, np.pi / 180 * 100])
#: steps (X mm, C deg): the X reversals with small C steps make narrow dips of ds/du
WANDER_STEPS = {
    "turns": [[3.371, -59.063], [18.298, -41.545], [17.846, -20.857], [-7.947, 10.814],
              [-6.834, -25.985], [-8.236, 46.778]],
    "strokes": [[24.969, 0.323], [-5.225, 0.524], [14.834, 1.145], [6.262, -37.38],
                [14.036, 1.15], [-16.979, 1.141], [4.774, -15.926], [22.211, -22.045],
                [16.442, 0.709]],
    "zigzag": [[24, 0.8], [-26, 1.2], [18, 0.6], [-28, 1.6], [-23, 10], [-27, 1.4],
               [13.5, 0.25], [10, 23]],
}


def wander_path(name: str):
    steps = np.array(WANDER_STEPS[name], dtype=float)
    return fit_points(np.cumsum(np.vstack([[0.0, 0.0], steps]), axis=0), SCALE, "cubic")


@pytest.mark.parametrize("name", sorted(WANDER_STEPS))
def test_constant_feed_samples_are_as_smooth_as_the_path(name: str) -> None:
    """Third differences of x(u(s_k)), s_k = k v dt, are at most (v dt)^3 max |x_sss| over
    their window (the divided-difference mean value bound) plus rounding: at dt = 1 ms any
    uneven error of u(s) would show up here multiplied by 1/dt^3 in the checker's jerk."""
    path = wander_path(name)
    v, dt = 100.0, 1e-3
    s = np.arange(0.0, path.length, v * dt)
    u = path.u_of_s(s)
    d3 = np.abs(np.diff(path.eval_u(u, 0)[0], 3, axis=0))
    # max |x_sss| over each window [u_k, u_k+3], densely in u (x_sss comes from u-derivatives)
    dense = u[:-3, None] + (u[3:] - u[:-3])[:, None] * np.linspace(0.0, 1.0, 96)[None, :]
    d = path.eval_u(dense.ravel(), 3)
    xsss = np.abs(arc_length_derivatives(d, SCALE)[3]).reshape((*dense.shape, 2))
    bound = 1.05 * xsss.max(axis=1) * (v * dt) ** 3
    rounding = 1e-12 * (1.0 + np.max(np.abs(path.eval_u(u, 0)[0]), axis=0))
    excess = d3 - bound - rounding
    assert np.all(excess <= 0), (np.max(excess), s[np.argmax(np.max(excess, axis=1))])


@pytest.mark.parametrize("name", sorted(WANDER_STEPS))
def test_round_trips_are_at_rounding(name: str) -> None:
    path = wander_path(name)
    s = np.linspace(0.0, path.length, 4001)
    assert np.max(np.abs(path.s_of_u(path.u_of_s(s)) - s)) <= 1e-13 * path.length
    u = np.linspace(*path.u_range, 4001)
    assert np.max(np.abs(path.u_of_s(path.s_of_u(u)) - u)) <= 1e-12 * path.u_range[1]


def test_near_cusp_interval_matches_adaptive_quadrature() -> None:
    """s(u) inside the knot interval with the deepest dip of ds/du, against scipy quad."""
    path = wander_path("zigzag")
    count = path.interval_lengths[1]
    i = int(np.argmax(count))
    assert count[i] > 4  # the dip was refined
    a, b = path.pp.x[i], path.pp.x[i + 1]
    speed = lambda x: float(np.linalg.norm(path.eval_u(np.array([x]), 1)[1, 0] * SCALE))  # noqa: E731
    u = np.linspace(a, b, 9)[1:]
    ref = [quad(speed, a, x, epsabs=0, epsrel=1e-13, limit=500)[0] for x in u]
    got = path.s_of_u(u) - path.breakpoints_s()[i]
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-13 * path.length)


def test_exact_cusp_arc_length() -> None:
    """pchip with both axes at an extremum: ds/du = 0 at the middle knot, |x_u| ~ |u - k|
    next to it; length and inversion stay exact (the knot is a leaf edge)."""
    path = fit_points(np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.5]]), SCALE, "pchip")
    speed = lambda x: float(np.linalg.norm(path.eval_u(np.array([x]), 1)[1, 0] * SCALE))  # noqa: E731
    knots = path.breakpoints_u()
    ref = sum(quad(speed, a, b, epsabs=0, epsrel=1e-13)[0] for a, b in pairwise(knots))
    assert path.length == pytest.approx(ref, rel=1e-12)
    s = np.linspace(0.0, path.length, 1001)
    assert np.max(np.abs(path.s_of_u(path.u_of_s(s)) - s)) <= 1e-13 * path.length
    assert np.all(np.diff(path.u_of_s(s)) > 0)


@pytest.mark.parametrize("naxes", [1, 2, 3, 6, 9])
def test_row_norms_are_the_euclidean_norms(naxes: int) -> None:
    """The column-by-column speed norm of the arc-length quadrature equals the norm of
    each row (to rounding), for any axis count."""
    from lookahead.geometry.piecewise import _row_norms

    y = np.random.default_rng(naxes).normal(size=(500, naxes)) * np.logspace(-3, 3, naxes)
    np.testing.assert_allclose(_row_norms(y), np.linalg.norm(y, axis=1), rtol=4e-16 * naxes)
    assert _row_norms(np.zeros((3, naxes))).tolist() == [0.0, 0.0, 0.0]
