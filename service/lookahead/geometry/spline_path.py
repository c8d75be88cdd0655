"""A `Path` backed by a vector-valued scipy piecewise polynomial x(u).

Arc length is integrated per knot interval with Gauss-Legendre quadrature (scipy has no
arc-length routine for PPoly); u(s) is inverted by safeguarded Newton steps inside the
bracketing interval.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator, PPoly

from lookahead.geometry.base import Path

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)


class SplinePath(Path):
    """x(u) given as a scipy PPoly with values of shape (naxes,), u over its breakpoints."""

    def __init__(self, pp: PPoly, path_scale: np.ndarray, continuity: int = 2) -> None:
        self.pp = pp
        self.path_scale = np.asarray(path_scale, dtype=float)
        self.naxes = int(self.path_scale.size)
        self._continuity = continuity
        self._derivs = [pp, pp.derivative(1), pp.derivative(2), pp.derivative(3)]
        self._knots = np.asarray(pp.x, dtype=float)
        self._s_knots = np.concatenate([[0.0], np.cumsum(self._interval_lengths())])

    # --- arc length -------------------------------------------------------------------
    def _speed(self, u: np.ndarray) -> np.ndarray:
        """sigma(u) = ||path_scale * dx/du||."""
        xu = self._derivs[1](u)
        return np.sqrt(np.sum((self.path_scale * xu) ** 2, axis=-1))

    def _interval_lengths(self) -> np.ndarray:
        a, b = self._knots[:-1], self._knots[1:]
        half = 0.5 * (b - a)
        u = (a + b)[:, None] * 0.5 + half[:, None] * _GL_NODES[None, :]
        return half * (self._speed(u.ravel()).reshape(u.shape) @ _GL_WEIGHTS)

    def _partial_length(self, idx: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Arc length from knot idx to u (u inside interval idx)."""
        a = self._knots[idx]
        half = 0.5 * (u - a)
        uu = (a + u)[:, None] * 0.5 + half[:, None] * _GL_NODES[None, :]
        return half * (self._speed(uu.ravel()).reshape(uu.shape) @ _GL_WEIGHTS)

    @property
    def length(self) -> float:
        return float(self._s_knots[-1])

    @property
    def u_range(self) -> tuple[float, float]:
        return float(self._knots[0]), float(self._knots[-1])

    def _interval(self, u: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self._knots, u, side="right") - 1, 0, len(self._knots) - 2)

    def s_of_u(self, u: np.ndarray) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), *self.u_range)
        idx = self._interval(u)
        return self._s_knots[idx] + self._partial_length(idx, u)

    def u_of_s(self, s: np.ndarray) -> np.ndarray:
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.length)
        idx = np.clip(np.searchsorted(self._s_knots, s, side="right") - 1, 0, len(self._knots) - 2)
        lo, hi = self._knots[idx], self._knots[idx + 1]
        s_lo, s_hi = self._s_knots[idx], self._s_knots[idx + 1]
        span = np.maximum(s_hi - s_lo, np.finfo(float).tiny)
        u = lo + (hi - lo) * (s - s_lo) / span
        for _ in range(30):
            err = s_lo + self._partial_length(idx, u) - s
            step = err / np.maximum(self._speed(u), np.finfo(float).tiny)
            u_new = np.clip(u - step, lo, hi)
            done = np.all(np.abs(u_new - u) <= 1e-14 * np.maximum(1.0, np.abs(u)))
            u = u_new
            if done:
                break
        return u

    # --- evaluation -------------------------------------------------------------------
    def eval_u(self, u: np.ndarray, order: int = 3) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), *self.u_range)
        return np.stack([self._derivs[k](u) for k in range(order + 1)])

    def breakpoints_s(self) -> np.ndarray:
        return self._s_knots.copy()

    def continuity(self) -> int:
        return self._continuity


def chord_parameters(points: np.ndarray, path_scale: np.ndarray) -> np.ndarray:
    """Cumulative chord length of `points` (n, naxes) in the path metric, starting at 0."""
    steps = np.sqrt(np.sum((np.diff(points, axis=0) * path_scale) ** 2, axis=1))
    return np.concatenate([[0.0], np.cumsum(steps)])


def fit_points(points: np.ndarray, path_scale: np.ndarray, method: str = "cubic") -> SplinePath:
    """Fit a point stream (n, naxes), n >= 2, with distinct consecutive points.

    method: 'cubic' (C2 interpolating, not-a-knot ends) or 'pchip' (C1, shape-preserving).
    The parameter u is the cumulative chord length in the path metric.
    """
    points = np.asarray(points, dtype=float)
    u = chord_parameters(points, path_scale)
    if method == "cubic":
        bc = "not-a-knot" if len(u) > 3 else "natural"
        return SplinePath(CubicSpline(u, points, axis=0, bc_type=bc), path_scale, continuity=2)
    if method == "pchip":
        return SplinePath(PchipInterpolator(u, points, axis=0), path_scale, continuity=1)
    raise ValueError(f"fit: unknown method {method!r}, expected 'cubic' or 'pchip'")
