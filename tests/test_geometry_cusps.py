"""Corners where ds/du vanishes (cusps of the parameterization: the tangent flips) for
every path kind, and CompositePath junctions from the pieces' cached end geometry."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.interpolate import PPoly

from lookahead.geometry import BSplinePath, CompositePath, PiecewisePath, fit_points
from lookahead.geometry.piecewise import evaluate_ends

SCALE = np.array([1.0, np.pi / 180 * 100])


def test_pchip_cusp_where_both_axes_reverse_is_a_corner() -> None:
    path = fit_points(np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.5]]), SCALE, "pchip")
    np.testing.assert_allclose(path.corners_s(), path.breakpoints_s()[1:2])
    s_j, _ = path.xss_jumps()
    assert s_j.size == 0  # a corner is not also a C1 knot to cap


def test_pchip_where_one_axis_reverses_turns_smoothly() -> None:
    """X reverses, C keeps going: the tangent is (0, c') from both sides, no corner; the
    curvature jumps (C1 knot) unless the turn is symmetric, and is reported as an x_ss
    jump instead."""
    path = fit_points(np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 2.0]]), SCALE, "pchip")
    assert path.corners_s().size == 0
    path = fit_points(np.array([[0.0, 0.0], [1.0, 1.0], [0.5, 3.0]]), SCALE, "pchip")
    assert path.corners_s().size == 0
    s_j, jumps = path.xss_jumps()
    np.testing.assert_allclose(s_j, path.breakpoints_s()[1:2])
    assert np.max(jumps) > 0.1


def test_cusp_with_rounding_level_speed_is_a_corner() -> None:
    """x_u = eps (1, 1) from both sides of u = 1 (parallel one-sided tangents, exact in
    floating point), but x(u) ~ -(u - 1)^2 (1, 1) around it: the path arrives along
    +(1, 1) and leaves along -(1, 1) (the tangent flips at u = 1 + eps/2). Measured by
    its vanishing speed, the knot is a corner."""
    eps = 2.0**-50
    # coefficients per interval (highest power first) of the local polynomial in u - u_i
    left = np.array([[-1.0, -1.0], [2.0 + eps, 2.0 + eps], [-1.0, -1.0]])  # -(1-u)^2 + eps u
    right = np.array([[-1.0, -1.0], [eps, eps], [-1.0 + eps, -1.0 + eps]])
    path = PiecewisePath(PPoly(np.stack([left, right], axis=1), [0.0, 1.0, 2.0]), np.ones(2))
    assert path.corners_s() == pytest.approx([path.breakpoints_s()[1]])


@pytest.mark.parametrize("fit", ["cubic", "pchip"])
def test_smooth_fits_have_no_corners(fit: str) -> None:
    u = np.linspace(0, 6, 40)
    points = np.column_stack([30 * np.sin(u), 200 * u])
    assert fit_points(points, SCALE, fit).corners_s().size == 0


def cubic_piece(ctrl: np.ndarray) -> BSplinePath:
    return BSplinePath(3, [0, 0, 0, 0, 0.5, 1, 1, 1, 1], ctrl, SCALE)


def test_composite_junction_with_zero_speed_is_a_corner() -> None:
    """A piece that ends on a repeated control point has ds/du = 0 there: the junction is a
    corner even though the next piece continues in the arrival direction."""
    first = cubic_piece(np.array([[0, 0], [5, 1], [8, 2], [10, 3], [10, 3.0]]))
    second = cubic_piece(np.array([[10, 3], [12, 4], [15, 5], [18, 6], [20, 7.0]]))
    assert evaluate_ends(first).cusp.tolist() == [False, True]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no 0/0 noise on the way
        path = CompositePath([first, second])
        corners = path.corners_s()
    np.testing.assert_allclose(corners, [first.length])
    assert not np.any(np.isclose(path.xss_jumps()[0], first.length))


def test_composite_ends_match_arc_length_evaluation() -> None:
    """The cached end geometry equals eval_s at s = 0 and s = length; nested composites
    give the same junctions as the flat one."""
    rng = np.random.default_rng(4)
    pieces, start = [], np.zeros(2)
    for _ in range(6):
        ctrl = start + np.cumsum(rng.normal(size=(5, 2)) * [5, 20], axis=0)
        ctrl[0] = start
        pieces.append(cubic_piece(ctrl))
        start = ctrl[-1]
    flat = CompositePath(pieces)
    nested = CompositePath([CompositePath(pieces[:2]), pieces[2], CompositePath(pieces[3:])])
    ends = flat.ends()
    for k, s in enumerate((0.0, flat.length)):
        d = flat.eval_s(np.array([s]), 2)[:, 0]
        np.testing.assert_allclose(ends.x[k], d[0], atol=1e-12)
        np.testing.assert_allclose(ends.xs[k], d[1], atol=1e-9)
        np.testing.assert_allclose(ends.xss[k], d[2], rtol=1e-6, atol=1e-9)
    assert nested.length == pytest.approx(flat.length, rel=1e-14)
    np.testing.assert_allclose(nested.corners_s(), flat.corners_s(), rtol=1e-13)
    assert flat.corners_s().size == 5  # random control polygons: every junction kinks
    for p, q in zip(nested.xss_jumps(), flat.xss_jumps(), strict=True):
        np.testing.assert_allclose(p, q, rtol=1e-12)
