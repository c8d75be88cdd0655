"""u(s) by the arc-length table: a cubic Hermite first guess from the speeds at the leaf
ends and Newton steps accepted without a further quadrature when their Taylor bound is
below rounding. On smooth paths one quadrature per sample suffices; near cusps (ds/du ~ 0)
the bracketed iteration still converges to the rounding of s."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.geometry import fit_points

SCALE = np.array([1.0, 1.0])
_EPS = np.finfo(float).eps


def cycloid(a: float, n: int = 400):
    """A trochoid x = t - a sin t, y = 1 - a cos t: near a = 1 its speed nearly vanishes
    once a turn (a near-cusp inside a knot interval)."""
    t = np.linspace(0.0, 6.0 * np.pi, n)
    return fit_points(np.column_stack([t - a * np.sin(t), 1.0 - a * np.cos(t)]), SCALE, "cubic")


def residual_floor(table, s: np.ndarray) -> np.ndarray:
    """The convergence floor of the inversion: 4 ulp of s plus its leaf's length."""
    idx = np.clip(np.searchsorted(table.s_edges, s, side="right") - 1, 0, table.edges.size - 2)
    return 4.0 * _EPS * (np.abs(s) + np.diff(table.s_edges)[idx])


@pytest.mark.parametrize("a", [0.3, 0.995, 0.99999])
def test_inversion_round_trips_to_the_rounding_of_s(a: float) -> None:
    path = cycloid(a)
    table = path._table
    s = np.sort(np.random.default_rng(7).uniform(0.0, path.length, 20000))
    u, count = table.invert(s)
    assert np.all(np.abs(table.s_of_u(u) - s) <= residual_floor(table, s))
    assert np.all(np.diff(u) >= 0)
    assert np.all(count >= 1) and np.all(count < 60)


def test_smooth_path_needs_about_one_quadrature_per_sample() -> None:
    """Away from near-cusps the Hermite guess and the unchecked Newton step converge in
    one quadrature almost everywhere (the linear guess with checked steps took 2)."""
    path = cycloid(0.3)
    s = np.linspace(0.0, path.length, 20001)
    _, count = path._table.invert(s)
    assert np.mean(count) <= 1.2
    assert np.max(count) <= 3


def test_near_cusp_samples_converge_within_a_few_steps() -> None:
    """Where sigma nearly vanishes the step needs its check (the Taylor bound is large
    there) and the bracket keeps it safe: a few quadratures there, one elsewhere."""
    path = cycloid(0.99999)
    s = np.linspace(0.0, path.length, 20001)
    _, count = path._table.invert(s)
    assert np.mean(count) <= 1.2
    assert np.max(count) <= 8


def test_result_does_not_depend_on_the_batch() -> None:
    """Streaming determinism: a sample's u does not depend on the other samples of the
    call, nor on which leaves' speeds were computed earlier."""
    s = np.random.default_rng(3).uniform(0.0, 1.0, 3000)
    whole = cycloid(0.995)
    parts = cycloid(0.995)
    s *= whole.length
    u_parts = np.concatenate([parts.u_of_s(c) for c in np.array_split(s, 37)])
    np.testing.assert_array_equal(whole.u_of_s(s), u_parts)
    np.testing.assert_array_equal(np.array([whole.u_of_s(x)[0] for x in s[:50]]), u_parts[:50])
