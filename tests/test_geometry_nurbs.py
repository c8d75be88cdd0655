"""B-spline / NURBS pieces, CompositePath, discretize."""


from itertools import pairwise

import numpy as np
import pytest
from scipy.integrate import quad

from lookahead.geometry import BSplinePath, CompositePath, NurbsPath, discretize

UNIT = np.array([1.0, 1.0])
SCALE = np.array([1.0, np.pi / 180 * 100])
W = np.sqrt(0.5)


def quarter_circle(radius: float = 50.0) -> NurbsPath:
    ctrl = radius * np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return NurbsPath(2, [0, 0, 0, 1, 1, 1], ctrl, [1.0, W, 1.0], UNIT)


def random_nurbs(degree: int, seed: int = 0) -> NurbsPath:
    rng = np.random.default_rng(seed)
    m = degree + 6
    inner = np.sort(rng.random(m - degree - 1)) * 3
    knots = np.concatenate([[0.0] * (degree + 1), inner, [3.0] * (degree + 1)])
    ctrl = np.cumsum(rng.random((m, 2)) * [10, 40], axis=0)
    return NurbsPath(degree, knots, ctrl, 0.5 + rng.random(m), SCALE)


def test_quarter_circle_stays_on_its_radius() -> None:
    arc = quarter_circle(50.0)
    x = arc.eval_u(np.linspace(0, 1, 10001), 0)[0]
    assert np.max(np.abs(np.hypot(x[:, 0], x[:, 1]) - 50.0)) < 1e-12 * 50
    assert arc.length == pytest.approx(np.pi * 25.0, rel=1e-12)
    d = arc.eval_s(np.linspace(0, arc.length, 101))
    assert np.allclose(np.linalg.norm(d[1], axis=1), 1.0, atol=1e-12)
    assert np.allclose(np.linalg.norm(d[2], axis=1), 1 / 50.0, rtol=1e-9)
    assert np.allclose(np.linalg.norm(d[3], axis=1), 1 / 50.0**2, rtol=1e-7)


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_nurbs_u_derivatives_match_finite_differences(degree: int) -> None:
    path = random_nurbs(degree, seed=degree)
    knots = np.unique(path.knots)
    u = (0.3 * knots[:-1] + 0.7 * knots[1:])  # inside spans, away from knots
    d, h = path.eval_u(u), 1e-6
    for k in range(3):
        fd = (path.eval_u(u + h, k)[k] - path.eval_u(u - h, k)[k]) / (2 * h)
        assert np.allclose(fd, d[k + 1], rtol=1e-5, atol=1e-5 * np.max(np.abs(d[k + 1]))), k


def test_nurbs_s_derivatives_and_arc_length() -> None:
    path = random_nurbs(3, seed=11)
    s_k = path.breakpoints_s()
    s = 0.5 * (s_k[:-1] + s_k[1:])
    d, h = path.eval_s(s), 1e-4
    for k in range(3):
        fd = (path.eval_s(s + h)[k] - path.eval_s(s - h)[k]) / (2 * h)
        assert np.allclose(fd, d[k + 1], rtol=1e-5, atol=1e-6 * np.max(np.abs(d[k + 1])))
    speed = lambda u: float(np.linalg.norm(path.eval_u(np.array([u]), 1)[1, 0] * SCALE))  # noqa: E731
    spans = np.unique(path.knots)
    ref = sum(quad(speed, a, b, epsabs=0, epsrel=1e-13)[0] for a, b in pairwise(spans))
    assert path.length == pytest.approx(ref, rel=1e-11)
    s = np.linspace(0, path.length, 501)
    assert np.max(np.abs(path.s_of_u(path.u_of_s(s)) - s)) <= 1e-9 * path.length


def test_bspline_without_weights_equals_unit_weights() -> None:
    rng = np.random.default_rng(5)
    ctrl = rng.random((7, 2)) * 10
    knots = [0, 0, 0, 0, 1, 2, 2.5, 4, 4, 4, 4]
    a = BSplinePath(3, knots, ctrl, SCALE)
    b = NurbsPath(3, knots, ctrl, np.ones(7) * 2.5, SCALE)
    u = np.linspace(0, 4, 301)
    assert np.allclose(a.eval_u(u), b.eval_u(u), atol=1e-10)
    assert a.continuity() == 2 and a.corners_s().size == 0


def test_polyline_has_corners_at_its_knots() -> None:
    line = BSplinePath(1, [0, 0, 1, 2, 2], np.array([[0, 0], [3, 0], [3, 4.0]]), UNIT)
    assert line.length == pytest.approx(7.0)
    assert np.allclose(line.corners_s(), [3.0])


def test_composite_concatenates_and_finds_corners() -> None:
    arc = quarter_circle(50.0)  # ends at (0, 50) heading -x
    tangent = BSplinePath(1, [0, 0, 1, 1], np.array([[0, 50.0], [-20, 50.0]]), UNIT)
    kinked = BSplinePath(1, [0, 0, 1, 1], np.array([[-20, 50.0], [-20, 80.0]]), UNIT)
    path = CompositePath([arc, tangent, kinked])
    assert path.length == pytest.approx(arc.length + 50.0)
    assert np.allclose(path.corners_s(), [arc.length + 20.0])
    assert path.continuity() == 1  # curvature jumps from 1/50 to 0 at the tangent junction
    s_j, jumps = path.xss_jumps()
    assert np.allclose(s_j, [arc.length]) and np.max(jumps) == pytest.approx(1 / 50.0)
    s = np.array([10.0, arc.length + 5.0, arc.length + 30.0])
    x = path.eval_s(s, 1)
    assert np.allclose(x[0], [arc.eval_s(np.array([10.0]), 0)[0, 0], [-5, 50], [-20, 60]])
    assert np.allclose(x[1][1:], [[-1, 0], [0, 1]])
    assert np.allclose(path.s_of_u(path.u_of_s(np.linspace(0, path.length, 50))),
                       np.linspace(0, path.length, 50))


def test_composite_rejects_gaps() -> None:
    arc = quarter_circle(50.0)
    away = BSplinePath(1, [0, 0, 1, 1], np.array([[1.0, 50.0], [-20, 50.0]]), UNIT)
    with pytest.raises(ValueError, match=r"pieces\[1\]"):
        CompositePath([arc, away])


def test_discretize_stays_within_chord_tolerance() -> None:
    rng = np.random.default_rng(2)
    path = BSplinePath(3, [0, 0, 0, 0, 1, 2, 3, 3, 3, 3], rng.random((6, 2)) * 100, UNIT)
    tol = 0.01
    pts = discretize(path, tol)
    dense = path.eval_u(np.linspace(*path.u_range, 40001), 0)[0]
    # each dense point is within tol of the polyline (distance to nearest segment)
    a, b = pts[:-1], pts[1:]
    ab = b - a
    t = np.clip(np.einsum("kij,ij->ki", dense[:, None] - a, ab) / np.sum(ab * ab, 1), 0, 1)
    dist = np.linalg.norm(dense[:, None] - (a + t[..., None] * ab), axis=2).min(axis=1)
    assert dist.max() <= tol * 1.01
    assert np.allclose(pts[[0, -1]], dense[[0, -1]])
    assert len(discretize(path, tol / 100)) > 5 * len(pts)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(degree=2, knots=[0, 0, 0, 1, 0.5, 1], ctrl=np.zeros((3, 2))), r"knots\[4\]"),
        (dict(degree=2, knots=[0, 0, 0, 1, 1], ctrl=np.zeros((3, 2))), "knots: expected"),
        (dict(degree=2, knots=[0, 0, 0, 1, 1, 1], ctrl=np.zeros((3, 2)), weights=[1, 0, 1]),
         r"weights\[1\]"),
        (dict(degree=2, knots=[0, 0, 0, 1, 1, 1], ctrl=np.zeros((3, 2)), weights=[1, -2, 1]),
         r"weights\[1\]"),
        (dict(degree=2, knots=[0, 0, 0, 1, 1, 1], ctrl=np.array([[0, 0], [1, np.nan], [2, 2]])),
         r"ctrl\[1\]"),
        (dict(degree=2, knots=[0, 0, 0, np.inf, 1, 1], ctrl=np.zeros((3, 2))), r"knots\[3\]"),
        (dict(degree=2, knots=[0, 0, 0.5, 1, 1, 1], ctrl=np.zeros((3, 2))), r"knots\[2\].*clamped"),
        (dict(degree=6, knots=[0] * 7 + [1] * 7, ctrl=np.zeros((7, 2))), "degree"),
        (dict(degree=2, knots=[0, 0, 0, 1, 1, 1], ctrl=np.zeros((3, 3))), "ctrl: expected shape"),
        (dict(degree=1, knots=[0, 0, 1, 1, 1, 2, 2], ctrl=np.zeros((5, 2))),
         r"knots\[2\].*multiplicity"),
    ],
)
def test_bad_pieces_raise_naming_the_index(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        BSplinePath(path_scale=UNIT, **kwargs)
