"""Whole-stream fits (cubic, pchip): derivatives, arc length, u(s), continuity, bad input."""


from itertools import pairwise

import numpy as np
import pytest
from scipy.integrate import quad

from lookahead.geometry import fit_points
from lookahead.geometry.base import Path

SCALE = np.array([1.0, np.pi / 180 * 100])


def wavy_points(n: int = 60, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = np.cumsum(0.5 + rng.random(n))
    return np.column_stack([20 * np.sin(u / 7) + 3 * u, 40 * np.cos(u / 5) + 10 * u])


def fd_check(path: Path, s: np.ndarray, h: float) -> tuple[float, float, float]:
    """Max errors of d/ds, d2/ds2, d3/ds3 of eval_s against central differences."""
    d = path.eval_s(s)
    plus, minus = path.eval_s(s + h), path.eval_s(s - h)
    errs = []
    for k in range(3):
        fd = (plus[k] - minus[k]) / (2 * h)
        errs.append(float(np.max(np.abs(fd - d[k + 1])) / (np.max(np.abs(d[k + 1])) + 1e-12)))
    return tuple(errs)


def interior_s(path: Path, n: int = 200) -> np.ndarray:
    """Arc lengths away from the knots (FD across a C1 knot would be meaningless)."""
    s_k = path.breakpoints_s()
    mid = 0.5 * (s_k[:-1] + s_k[1:])
    return mid[:: max(1, len(mid) // n)]


@pytest.mark.parametrize("method", ["cubic", "pchip"])
def test_s_derivatives_match_finite_differences(method: str) -> None:
    path = fit_points(wavy_points(), SCALE, method)
    errs = fd_check(path, interior_s(path), 1e-4)
    assert max(errs) < 1e-5, errs


@pytest.mark.parametrize("method", ["cubic", "pchip"])
def test_u_derivatives_match_finite_differences(method: str) -> None:
    path = fit_points(wavy_points(), SCALE, method)
    u = path.u_of_s(interior_s(path))
    d, h = path.eval_u(u), 1e-5
    for k in range(3):
        fd = (path.eval_u(u + h)[k] - path.eval_u(u - h)[k]) / (2 * h)
        assert np.max(np.abs(fd - d[k + 1])) < 1e-5 * (1 + np.max(np.abs(d[k + 1])))


@pytest.mark.parametrize("method", ["cubic", "pchip"])
def test_arc_length_matches_quadrature(method: str) -> None:
    path = fit_points(wavy_points(30), SCALE, method)
    speed = lambda u: float(np.linalg.norm(path.eval_u(np.array([u]), 1)[1, 0] * SCALE))  # noqa: E731
    knots = path.u_of_s(path.breakpoints_s())
    ref = sum(quad(speed, a, b, epsabs=0, epsrel=1e-13)[0] for a, b in pairwise(knots))
    assert path.length == pytest.approx(ref, rel=1e-11)
    u = np.linspace(*path.u_range, 37)[1:-1]
    s_ref = [sum(quad(speed, a, min(b, x), epsabs=0, epsrel=1e-13)[0]
                 for a, b in pairwise(knots) if a < x) for x in u]
    assert np.allclose(path.s_of_u(u), s_ref, rtol=1e-10, atol=0)


def test_u_of_s_inverts_s_of_u_to_1e9() -> None:
    path = fit_points(wavy_points(200), SCALE)
    s = np.linspace(0, path.length, 5001)
    back = path.s_of_u(path.u_of_s(s))
    assert np.max(np.abs(back - s)) <= 1e-9 * path.length
    # unit speed in the path metric: ||scale * x_s|| = 1
    xs = path.eval_s(s, 1)[1]
    assert np.allclose(np.linalg.norm(xs * SCALE, axis=1), 1.0, atol=1e-12)


def one_sided(path, order: int) -> tuple[np.ndarray, np.ndarray]:
    """d^order x/du^order from both sides of the interior knots (polynomial pieces)."""
    dp = path.pp.derivative(order) if order else path.pp
    x = dp.x[1:-1]
    h = np.diff(dp.x)[:-1]
    left = np.stack([np.polyval(dp.c[:, i, :], h[i]) for i in range(len(x))])
    return left, dp(x)


def test_cubic_is_c2_and_pchip_c1_at_knots() -> None:
    pts = wavy_points()
    cubic, pchip = fit_points(pts, SCALE, "cubic"), fit_points(pts, SCALE, "pchip")
    for order in range(3):
        left, right = one_sided(cubic, order)
        assert np.max(np.abs(left - right)) < 1e-9 * (1 + np.max(np.abs(right)))
    left, right = one_sided(pchip, 2)
    assert np.max(np.abs(left - right)) > 1e-3  # pchip really is only C1...
    assert pchip.continuity() == 1 and cubic.continuity() == 2
    s_j, jumps = pchip.xss_jumps()  # ...and reports where
    assert len(s_j) == len(pts) - 2 and np.max(jumps) > 0


def test_pchip_never_overshoots() -> None:
    rng = np.random.default_rng(3)
    steps = np.where(rng.random(80) < 0.5, 0.0, rng.random(80) * 5)
    pts = np.column_stack([np.cumsum(rng.random(80) + 0.1), np.cumsum(steps) * 3])
    path = fit_points(pts, SCALE, "pchip")
    knots = path.pp.x
    u = np.linspace(knots[0], knots[-1], 20001)
    x = path.eval_u(u, 0)[0]
    idx = np.clip(np.searchsorted(knots, u, side="right") - 1, 0, len(knots) - 2)
    for axis in range(2):
        lo = np.minimum(pts[idx, axis], pts[idx + 1, axis])
        hi = np.maximum(pts[idx, axis], pts[idx + 1, axis])
        assert np.all(x[:, axis] >= lo - 1e-9) and np.all(x[:, axis] <= hi + 1e-9)


def test_fit_interpolates_points() -> None:
    pts = wavy_points()
    for method in ("cubic", "pchip"):
        path = fit_points(pts, SCALE, method)
        assert np.allclose(path.eval_u(path.pp.x, 0)[0], pts, atol=1e-9)


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (np.array([[0, 0], [1, np.nan], [2, 2]]), r"points\[1\]"),
        (np.array([[0, 0], [1, 1], [2, np.inf]]), r"points\[2\]"),
        (np.zeros((4, 3)), "shape"),
        (np.array([[0, 0], [1, 1], [1, 1], [2, 2]]), r"points\[2\] repeats"),
        (np.array([[0.0, 0.0]]), "at least 2"),
    ],
)
def test_bad_points_raise_naming_the_row(points: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        fit_points(points, SCALE)


def test_unknown_method() -> None:
    with pytest.raises(ValueError, match="method"):
        fit_points(wavy_points(), SCALE, "quintic")


def test_large_evaluations_are_chunked_and_unchanged(monkeypatch):
    """scipy's PPoly call holds the GIL for its whole call, so a path evaluates at most
    EVAL_CHUNK points per call (a planning thread must not starve the real-time pacer);
    the chunked values are the same to the bit."""
    import numpy as np
    from scipy.interpolate import PPoly

    from lookahead.geometry import piecewise

    rng = np.random.default_rng(7)
    x = np.cumsum(rng.uniform(0.5, 2.0, 41))
    pp = PPoly(rng.normal(size=(4, 40, 3)), x)
    path = piecewise.PiecewisePath(pp, np.ones(3))
    u = np.sort(rng.uniform(x[0], x[-1], 5003))
    whole = (path.eval_u(u), path.eval_u_derivatives(u), path._speed(u))
    sizes: list[int] = []
    real_call = PPoly.__call__

    def counting(self, xs, *a, **kw):
        sizes.append(np.asarray(xs).size)
        return real_call(self, xs, *a, **kw)

    monkeypatch.setattr(piecewise, "EVAL_CHUNK", 500)
    monkeypatch.setattr(PPoly, "__call__", counting)
    chunked = (path.eval_u(u), path.eval_u_derivatives(u), path._speed(u))
    assert sizes and max(sizes) <= 500
    assert np.array_equal(whole[0], chunked[0]) and np.array_equal(whole[2], chunked[2])
    assert all(np.array_equal(a, b) for a, b in zip(whole[1], chunked[1], strict=True))
