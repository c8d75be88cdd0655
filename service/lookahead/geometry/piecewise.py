"""A `Path` over scipy piecewise polynomials: polynomial (x = A(u)) or rational
(x = A(u) / w(u), the homogeneous form of a NURBS).

Derivatives of a rational curve come from the quotient rule applied to the exact
derivatives of A and w:
  x' = (A' - w' x) / w,  x'' = (A'' - 2 w' x' - w'' x) / w,
  x''' = (A''' - 3 w' x'' - 3 w'' x' - w''' x) / w.
Arc length and u(s) come from `ArcLengthTable`. One-sided values at the breakpoints give
the tangent corners (where the machine must stop) and the jumps of d2x/ds2 (where a
planner caps the feed, DESIGN.md "Pitfalls"). A breakpoint where ds/du (nearly) vanishes
is a cusp of the parameterization (e.g. pchip where every axis has an extremum: the
tangent flips) and is a corner too, however the one-sided tangents come out of rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline, PPoly

from lookahead.geometry.arclength import ArcLengthTable, Leaves
from lookahead.geometry.base import Path, arc_length_derivatives

#: default angle (rad) between one-sided unit tangents above which a knot is a corner
CORNER_TOL_RAD = 1e-6
#: a knot (or path end) where ds/du is below this fraction of the adjacent intervals'
#: mean speed (arc length / parameter span) is a cusp: a corner. Rounding puts ~1e-16
#: there at an exact cusp; a near-cusp above this is smooth and left to the planners.
CUSP_SPEED_REL = 1e-6
_TINY = np.finfo(float).tiny


@dataclass(frozen=True)
class PathEnds:
    """A path's geometry at its start (row 0) and its end (row 1), from inside the path:
    x, x_s, x_ss (each (2, naxes), axis units per path unit^k), ds/du `sigma` (2,) and the
    `mean_speed` length / parameter span (for relative thresholds)."""

    x: np.ndarray
    xs: np.ndarray
    xss: np.ndarray
    sigma: np.ndarray
    mean_speed: float

    @property
    def cusp(self) -> np.ndarray:
        """(2,) True where ds/du (nearly) vanishes at that end: its tangent is undefined."""
        return self.sigma < CUSP_SPEED_REL * self.mean_speed


def evaluate_ends(path: Path) -> PathEnds:
    """`PathEnds` of any path, evaluated at its u_range ends (no arc-length inversion)."""
    u = np.asarray(path.u_range, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        sigma, xs, xss, _ = arc_length_derivatives(path.eval_u(u, 3), path.path_scale)
    span = float(u[1] - u[0])
    return PathEnds(path.eval_u(u, 0)[0], xs, xss, sigma, path.length / max(span, _TINY))


def path_ends(path: Path) -> PathEnds:
    """`path.ends()` where the path caches it (`PiecewisePath`, `CompositePath`), else
    `evaluate_ends(path)`."""
    cached = getattr(path, "ends", None)
    return cached() if callable(cached) else evaluate_ends(path)


def ppoly_from_bspline(spline: BSpline) -> PPoly:
    """The PPoly of a (vector-valued) scipy BSpline over its nonzero knot intervals.

    `PPoly.from_spline` handles scalar coefficients only; here every coefficient row
    comes from `BSpline.__call__(x, nu=m)` at the left end of each interval, so a piece
    depends only on its own knots and control points (needed for streaming determinism).
    """
    t, k = spline.t, spline.k
    x = np.unique(t[k : len(t) - k])
    left = x[:-1]
    rows = [spline(left, nu=m) / math.factorial(m) for m in range(k, -1, -1)]
    return PPoly(np.stack(rows), x)


#: points per scipy PPoly evaluation. scipy's PPoly.__call__ holds the GIL for its whole
#: call (about 0.16 us per point and axis-vector on the 2-core machine): one call on a
#: replan's million quadrature nodes held it for up to 163 ms, so a planning worker thread
#: kept the service's pacer thread from publishing for longer than its 50 ms lead (real-time
#: underruns on the 100k-line program). Chunks of this size hold it for about 3 ms; the
#: values are per point, so chunking changes no bit. Overhead: one call per chunk (~10 us).
EVAL_CHUNK = 16384


def _evaluate(pp: PPoly, u: np.ndarray) -> np.ndarray:
    """pp(u), a 1-D u in chunks of at most EVAL_CHUNK points (the GIL is released between
    them)."""
    u = np.asarray(u)
    if u.ndim != 1 or u.size <= EVAL_CHUNK:
        return pp(u)
    return np.concatenate([pp(u[i:i + EVAL_CHUNK]) for i in range(0, u.size, EVAL_CHUNK)])


def _horner_at(c: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Evaluate polynomial coefficient columns c (k+1, n, ...) at local offsets h (n,)."""
    h = h.reshape((-1,) + (1,) * (c.ndim - 2))
    out = c[0]
    for row in c[1:]:
        out = out * h + row
    return out


def _quotient(a: list[np.ndarray], w: list[np.ndarray]) -> list[np.ndarray]:
    """x and its u-derivatives from those of the homogeneous numerator a and weight w."""
    inv = 1.0 / w[0]
    x = [a[0] * inv]
    if len(a) > 1:
        x.append((a[1] - w[1] * x[0]) * inv)
    if len(a) > 2:
        x.append((a[2] - 2.0 * w[1] * x[1] - w[2] * x[0]) * inv)
    if len(a) > 3:
        x.append((a[3] - 3.0 * w[1] * x[2] - 3.0 * w[2] * x[1] - w[3] * x[0]) * inv)
    return x


class PiecewisePath(Path):
    """x(u) = A(u) [/ w(u)] with A a PPoly of values (naxes,), w an optional scalar PPoly
    on the same strictly increasing breakpoints. u is the native parameter; s is the arc
    length in the metric ||path_scale * dx||."""

    def __init__(
        self,
        pp: PPoly,
        path_scale: np.ndarray,
        weight: PPoly | None = None,
        continuity: int | None = None,
        corner_tol_rad: float = CORNER_TOL_RAD,
        leaves: Leaves | None = None,
    ) -> None:
        self.pp = pp
        self.path_scale = np.asarray(path_scale, dtype=float).reshape(-1)
        self.naxes = int(self.path_scale.size)
        if pp.c.ndim != 3 or pp.c.shape[2] != self.naxes:
            raise ValueError(f"path: polynomial values must have {self.naxes} axes")
        self._knots = np.asarray(pp.x, dtype=float)
        if np.any(np.diff(self._knots) <= 0):
            raise ValueError("path: breakpoints must be strictly increasing")
        self._numer = [pp] + [pp.derivative(j) for j in (1, 2, 3)]
        self._weight = None if weight is None else [weight] + [
            weight.derivative(j) for j in (1, 2, 3)
        ]
        self.corner_tol_rad = corner_tol_rad
        self._table = ArcLengthTable(self._speed, self._knots, leaves)
        self._sides: tuple[np.ndarray, np.ndarray] | None = None
        self._corners: np.ndarray | None = None
        self._ends: PathEnds | None = None
        self._continuity: int | None = continuity

    # --- evaluation -------------------------------------------------------------------
    def _raw(self, u: np.ndarray, order: int) -> list[np.ndarray]:
        a = [_evaluate(self._numer[j], u) for j in range(order + 1)]
        if self._weight is None:
            return a
        w = [_evaluate(self._weight[j], u).reshape(-1, 1) for j in range(order + 1)]
        return _quotient(a, w)

    def eval_u(self, u: np.ndarray, order: int = 3) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), *self.u_range)
        return np.stack(self._raw(u, order))

    def eval_u_derivatives(self, u: np.ndarray, order: int = 3) -> list[np.ndarray]:
        """d^k x/du^k for k = 1..order, each (n, naxes): `eval_u` without the position
        (not evaluated at all for a polynomial curve; a rational one needs it)."""
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), *self.u_range)
        if self._weight is None:
            return [_evaluate(self._numer[j], u) for j in range(1, order + 1)]
        return self._raw(u, order)[1:]

    def _speed(self, u: np.ndarray) -> np.ndarray:
        """sigma(u) = ||path_scale * dx/du||."""
        # a polynomial curve needs only dx/du (not x): half the evaluations of the
        # arc-length quadrature and inversion, the same values
        xu = _evaluate(self._numer[1], u) if self._weight is None else self._raw(u, 1)[1]
        return _row_norms(self.path_scale * xu)

    # --- arc length -------------------------------------------------------------------
    @property
    def length(self) -> float:
        return self._table.length

    @property
    def u_range(self) -> tuple[float, float]:
        return float(self._knots[0]), float(self._knots[-1])

    def s_of_u(self, u: np.ndarray) -> np.ndarray:
        return self._table.s_of_u(u)

    def u_of_s(self, s: np.ndarray) -> np.ndarray:
        return self._table.u_of_s(s)

    def breakpoints_s(self) -> np.ndarray:
        return self._table.s_knots.copy()

    def breakpoints_u(self) -> np.ndarray:
        """The breakpoints in u, matching `breakpoints_s()` entry by entry."""
        return self._knots.copy()

    @property
    def interval_lengths(self) -> tuple[np.ndarray, np.ndarray]:
        """(arc length, number of quadrature leaves) per knot interval."""
        return self._table.lengths, self._table.leaves.count

    @property
    def leaves(self) -> Leaves:
        """The arc-length quadrature leaves, for reuse by streaming fits."""
        return self._table.leaves

    def ends(self) -> PathEnds:
        """The geometry at both ends (cached: a path is immutable)."""
        if self._ends is None:
            self._ends = evaluate_ends(self)
        return self._ends

    # --- one-sided values at interior breakpoints -------------------------------------
    def _side_derivs_s(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x_s and x_ss from the left and right of every interior breakpoint (shape
        (2 sides, 2 orders, m, naxes)), their arc lengths (m,) and whether ds/du nearly
        vanishes there (m,) (see `CUSP_SPEED_REL`)."""
        if self._sides is not None:
            return self._sides
        inner = np.arange(1, len(self._knots) - 1)
        h = self._knots[inner] - self._knots[inner - 1]
        out, sigma = [], []
        for cols, hh in ((inner - 1, h), (inner, np.zeros_like(h))):
            a = [_horner_at(self._numer[j].c[:, cols], hh) for j in range(3)]
            if self._weight is None:
                x = a
            else:
                w = [_horner_at(self._weight[j].c[:, cols], hh).reshape(-1, 1) for j in range(3)]
                x = _quotient(a, w)
            out.append(_s_derivatives(x[1], x[2], self.path_scale))
            sigma.append(np.linalg.norm(x[1] * self.path_scale, axis=-1))
        mean_speed = self._table.lengths / np.diff(self._knots)
        ref = np.maximum(mean_speed[:-1], mean_speed[1:])
        cusp = np.minimum(sigma[0], sigma[1]) < CUSP_SPEED_REL * ref
        self._sides = (np.stack(out), self._table.s_knots[inner], cusp)
        return self._sides

    def _corner_mask(self) -> np.ndarray:
        """(m,) True at interior breakpoints that are corners: cusps, or unit tangents
        from both sides more than `corner_tol_rad` apart."""
        if self._corners is None:
            sides, _, cusp = self._side_derivs_s()
            self._corners = cusp | (tangent_angle(sides[0, 0], sides[1, 0], self.path_scale)
                                    > self.corner_tol_rad)
        return self._corners

    def corners_s(self) -> np.ndarray:
        _, s_inner, _ = self._side_derivs_s()
        return s_inner[self._corner_mask()]

    def xss_jumps(self) -> tuple[np.ndarray, np.ndarray]:
        """(s of interior breakpoints (m,), |jump of d2x/ds2| per axis (m, naxes)) away
        from corners: where a C1 path needs a feed cap sqrt(jmax*dt/|jump|)."""
        sides, s_inner, _ = self._side_derivs_s()
        keep = ~self._corner_mask()
        return s_inner[keep], np.abs(sides[1, 1] - sides[0, 1])[keep]

    def continuity(self) -> int:
        """The declared continuity, else measured (and cached) from the x_ss jumps."""
        if self._continuity is None:
            self._continuity = self._measured_continuity()
        return self._continuity

    def _measured_continuity(self) -> int:
        _, jumps = self.xss_jumps()
        if not jumps.size:
            return 2
        sides, _, _ = self._side_derivs_s()
        smooth = sides[:, 1][:, ~self._corner_mask()]  # x_ss is meaningless at cusps
        scale = np.max(np.abs(smooth)) + 1.0 / max(self.length, _TINY)
        return 2 if np.max(jumps) <= 1e-8 * scale else 1


def tangent_angle(a: np.ndarray, b: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Angle (rad) between tangents a and b (n, naxes) in the path metric (pi/2 where
    either is zero)."""
    ta, tb = a * scale, b * scale
    cos = np.sum(ta * tb, axis=-1) / np.maximum(
        np.linalg.norm(ta, axis=-1) * np.linalg.norm(tb, axis=-1), _TINY)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def _s_derivatives(xu: np.ndarray, xuu: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """x_s and x_ss from x_u and x_uu (chain rule through sigma = ||scale * x_u||;
    meaningless, but finite or inf without warnings, where sigma = 0: cusps)."""
    w = scale**2
    sigma = np.maximum(np.sqrt(np.sum(w * xu * xu, axis=-1)), _TINY)[:, None]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        sigma_u = np.sum(w * xu * xuu, axis=-1)[:, None] / sigma
        xs = xu / sigma
        xss = xuu / sigma**2 - xu * sigma_u / sigma**3
    return np.stack([xs, xss])


def _row_norms(y: np.ndarray) -> np.ndarray:
    """||y[i]|| of each row of y (n, naxes), summed column by column: numpy's row sums
    over a few axes are about 3x slower (arc-length inversion calls this several times a
    sample). The same sequential sum np.sum does below 8 axes, so the same values there."""
    acc = y[..., 0] * y[..., 0]
    for j in range(1, y.shape[-1]):
        acc = acc + y[..., j] * y[..., j]
    return np.sqrt(acc)
