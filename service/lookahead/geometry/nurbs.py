"""B-spline and NURBS curve pieces (PROTOCOL.md kind = bspline | nurbs) as `Path` objects,
their concatenation `CompositePath`, and `discretize` (curve -> points within a chord
tolerance, the paper's section 2.1 "discretization" of continuous starting geometry).

A NURBS is evaluated as the homogeneous B-spline (w P, w) built with scipy `BSpline`;
position and derivatives up to 3rd come from the quotient rule (`piecewise.py`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.interpolate import BSpline

from lookahead.geometry.base import Path
from lookahead.geometry.piecewise import (
    CORNER_TOL_RAD,
    PathEnds,
    PiecewisePath,
    path_ends,
    ppoly_from_bspline,
    tangent_angle,
)

MAX_DEGREE = 5


def validate_bspline(
    degree: int,
    knots: Sequence[float] | np.ndarray,
    ctrl: np.ndarray,
    naxes: int,
    weights: Sequence[float] | np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Checked (knots, ctrl, weights) as float arrays; ValueError naming the bad index."""
    if int(degree) != degree or not 1 <= degree <= MAX_DEGREE:
        raise ValueError(f"degree: must be an integer in 1..{MAX_DEGREE}, got {degree!r}")
    degree = int(degree)
    ctrl = np.asarray(ctrl, dtype=float)
    if ctrl.ndim != 2 or ctrl.shape[1] != naxes:
        raise ValueError(f"ctrl: expected shape (m, {naxes}), got {ctrl.shape}")
    m = len(ctrl)
    if m < degree + 1:
        raise ValueError(f"ctrl: need at least degree + 1 = {degree + 1} points, got {m}")
    bad = np.flatnonzero(~np.all(np.isfinite(ctrl), axis=1))
    if bad.size:
        raise ValueError(f"ctrl[{bad[0]}] is not finite: {ctrl[bad[0]].tolist()}")
    knots = np.asarray(knots, dtype=float).reshape(-1)
    if knots.size != m + degree + 1:
        raise ValueError(
            f"knots: expected len(ctrl) + degree + 1 = {m + degree + 1} values, got {knots.size}"
        )
    bad = np.flatnonzero(~np.isfinite(knots))
    if bad.size:
        raise ValueError(f"knots[{bad[0]}] is not finite: {knots[bad[0]]}")
    down = np.flatnonzero(np.diff(knots) < 0)
    if down.size:
        i = down[0] + 1
        raise ValueError(f"knots[{i}] = {knots[i]} is less than knots[{i - 1}] = {knots[i - 1]}")
    for end, idx in (("start", range(1, degree + 1)), ("end", range(m, m + degree))):
        for i in idx:
            ref = knots[0] if end == "start" else knots[-1]
            if knots[i] != ref:
                raise ValueError(
                    f"knots[{i}]: not clamped at the {end} (first/last degree + 1 knots equal)"
                )
    if knots[degree] >= knots[m]:
        raise ValueError("knots: the parameter interval has zero length")
    interior = knots[degree + 1 : m]
    if interior.size:
        _, first, counts = np.unique(interior, return_index=True, return_counts=True)
        over = np.flatnonzero(counts > degree)
        if over.size:
            i = degree + 1 + first[over[0]]
            raise ValueError(f"knots[{i}]: interior multiplicity exceeds the degree {degree}")
    if weights is not None:
        weights = np.asarray(weights, dtype=float).reshape(-1)
        if weights.size != m:
            raise ValueError(f"weights: expected {m} values (one per control point)")
        bad = np.flatnonzero(~np.isfinite(weights) | (weights <= 0))
        if bad.size:
            raise ValueError(f"weights[{bad[0]}] must be finite and > 0, got {weights[bad[0]]}")
    return knots, ctrl, weights


class BSplinePath(PiecewisePath):
    """A clamped B-spline (degree 1..5) in axis space, or a NURBS when `weights` given.

    u is the knot parameter; continuity in s is measured at the knots (2 or 1), tangent
    breaks (e.g. every interior knot of a degree-1 spline) are `corners_s()`.
    """

    def __init__(
        self,
        degree: int,
        knots: Sequence[float] | np.ndarray,
        ctrl: np.ndarray,
        path_scale: np.ndarray,
        weights: Sequence[float] | np.ndarray | None = None,
        corner_tol_rad: float = CORNER_TOL_RAD,
    ) -> None:
        path_scale = np.asarray(path_scale, dtype=float).reshape(-1)
        knots, ctrl, weights = validate_bspline(degree, knots, ctrl, path_scale.size, weights)
        self.degree = int(degree)
        self.knots = knots
        self.ctrl = ctrl
        self.weights = weights
        if weights is None:
            self.spline = BSpline(knots, ctrl, self.degree)
            weight_pp = None
        else:
            self.spline = BSpline(knots, ctrl * weights[:, None], self.degree)
            weight_pp = ppoly_from_bspline(BSpline(knots, weights, self.degree))
        super().__init__(
            ppoly_from_bspline(self.spline), path_scale, weight=weight_pp,
            corner_tol_rad=corner_tol_rad,
        )


class NurbsPath(BSplinePath):
    """A NURBS piece: control points `ctrl` (m, naxes) with weights (m,), all > 0."""

    def __init__(
        self,
        degree: int,
        knots: Sequence[float] | np.ndarray,
        ctrl: np.ndarray,
        weights: Sequence[float] | np.ndarray,
        path_scale: np.ndarray,
        corner_tol_rad: float = CORNER_TOL_RAD,
    ) -> None:
        super().__init__(degree, knots, ctrl, path_scale, weights, corner_tol_rad)


class CompositePath(Path):
    """Paths concatenated end to end. The composite parameter u runs through the pieces'
    parameter ranges laid end to end; s is the sum of the pieces' arc lengths.

    Junctions whose unit tangents differ by more than `corner_tol_rad`, or where either
    side's ds/du nearly vanishes (a cusp, `PathEnds.cusp`), are corners.
    `join_tol` (relative to the axis range) bounds the position gap at a junction.
    Building is O(pieces) numpy on the pieces' cached `ends()` (pieces are immutable).
    """

    def __init__(
        self,
        pieces: Sequence[Path],
        corner_tol_rad: float = CORNER_TOL_RAD,
        join_tol: float = 1e-9,
    ) -> None:
        if not pieces:
            raise ValueError("pieces: need at least one piece")
        self.pieces = list(pieces)
        self.path_scale = np.asarray(self.pieces[0].path_scale, dtype=float)
        self.naxes = self.pieces[0].naxes
        self.corner_tol_rad = corner_tol_rad
        for i, p in enumerate(self.pieces):
            if p.naxes != self.naxes or not np.array_equal(p.path_scale, self.path_scale):
                raise ValueError(f"pieces[{i}]: axes or path_scale differ from pieces[0]")
        spans = np.array([p.u_range[1] - p.u_range[0] for p in self.pieces])
        self._u_off = np.concatenate([[0.0], np.cumsum(spans)])
        self._s_off = np.concatenate([[0.0], np.cumsum([p.length for p in self.pieces])])
        ends = [path_ends(p) for p in self.pieces]
        # (2 ends, pieces, ...) stacks of the pieces' start and end geometry
        self._end_x, self._end_xs, self._end_xss = (
            np.stack([getattr(e, f) for e in ends], axis=1) for f in ("x", "xs", "xss"))
        self._end_cusp = np.stack([e.cusp for e in ends], axis=1)
        starts, stops = self._end_x
        span = np.ptp(np.vstack([starts, stops]), axis=0)
        gap = np.abs(starts[1:] - stops[:-1])
        bad = np.flatnonzero(np.any(gap > join_tol * np.maximum(span, 1.0), axis=1))
        if bad.size:
            i = int(bad[0]) + 1
            raise ValueError(f"pieces[{i}]: starts {gap[i - 1].max():.3g} away from the "
                             "previous end")
        self._ends_cache: PathEnds | None = None

    @property
    def length(self) -> float:
        return float(self._s_off[-1])

    @property
    def u_range(self) -> tuple[float, float]:
        return 0.0, float(self._u_off[-1])

    def _dispatch(self, values: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(offsets, values, side="right") - 1, 0, len(self.pieces) - 1)

    def eval_u(self, u: np.ndarray, order: int = 3) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), *self.u_range)
        idx = self._dispatch(u, self._u_off)
        out = np.empty((order + 1, u.size, self.naxes))
        for i in np.unique(idx):
            sel = idx == i
            local = u[sel] - self._u_off[i] + self.pieces[i].u_range[0]
            out[:, sel] = self.pieces[i].eval_u(local, order)
        return out

    def s_of_u(self, u: np.ndarray) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), *self.u_range)
        idx = self._dispatch(u, self._u_off)
        out = np.empty(u.size)
        for i in np.unique(idx):
            sel = idx == i
            local = u[sel] - self._u_off[i] + self.pieces[i].u_range[0]
            out[sel] = self._s_off[i] + self.pieces[i].s_of_u(local)
        return out

    def u_of_s(self, s: np.ndarray) -> np.ndarray:
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.length)
        idx = self._dispatch(s, self._s_off)
        out = np.empty(s.size)
        for i in np.unique(idx):
            sel = idx == i
            local = self.pieces[i].u_of_s(s[sel] - self._s_off[i])
            out[sel] = local - self.pieces[i].u_range[0] + self._u_off[i]
        return out

    def breakpoints_s(self) -> np.ndarray:
        parts = [p.breakpoints_s() + off for p, off in zip(self.pieces, self._s_off, strict=False)]
        return np.unique(np.concatenate(parts))

    def ends(self) -> PathEnds:
        """The geometry at both ends: the first piece's start, the last piece's end."""
        if self._ends_cache is None:
            first, last = path_ends(self.pieces[0]), path_ends(self.pieces[-1])
            self._ends_cache = PathEnds(
                *(np.stack([getattr(first, f)[0], getattr(last, f)[1]])
                  for f in ("x", "xs", "xss", "sigma")),
                mean_speed=self.length / max(self.u_range[1], 1e-300))
        return self._ends_cache

    def _junctions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(s, is_corner, |jump of x_ss| per axis) at each junction between pieces."""
        s = self._s_off[1:-1]
        left, right = self._end_xs[1, :-1], self._end_xs[0, 1:]
        corner = (self._end_cusp[1, :-1] | self._end_cusp[0, 1:]
                  | (tangent_angle(left, right, self.path_scale) > self.corner_tol_rad))
        with np.errstate(invalid="ignore"):  # inf - inf at cusps, which are corners
            jumps = np.abs(self._end_xss[0, 1:] - self._end_xss[1, :-1])
        return s, corner, jumps

    def corners_s(self) -> np.ndarray:
        s, corner, _ = self._junctions()
        inner = [p.corners_s() + off for p, off in zip(self.pieces, self._s_off, strict=False)]
        return np.unique(np.concatenate([s[corner], *inner]))

    def xss_jumps(self) -> tuple[np.ndarray, np.ndarray]:
        """(s, |jump of d2x/ds2| per axis) at non-corner knots and junctions."""
        s, corner, jumps = self._junctions()
        s_all, j_all = [s[~corner]], [jumps[~corner]]
        for p, off in zip(self.pieces, self._s_off, strict=False):
            if isinstance(p, PiecewisePath | CompositePath):
                ps, pj = p.xss_jumps()
                s_all.append(ps + off)
                j_all.append(pj)
        s_cat, j_cat = np.concatenate(s_all), np.concatenate(j_all)
        order = np.argsort(s_cat, kind="stable")
        return s_cat[order], j_cat[order]

    def continuity(self) -> int:
        _, corner, jumps = self._junctions()
        xss = self._end_xss[~self._end_cusp]
        scale = float(np.max(np.abs(xss))) if xss.size else 0.0
        smooth = np.all(jumps[~corner] <= 1e-8 * (scale + 1.0 / max(self.length, 1e-300)))
        return min([p.continuity() for p in self.pieces] + [2 if smooth else 1])


def discretize(path: Path, chord_tol: float, max_passes: int = 60) -> np.ndarray:
    """Points (n, naxes) on `path`, including its ends, breakpoints and corners, such that
    the curve between consecutive points stays within `chord_tol` (path units, path metric)
    of the chord. Intervals are bisected in u until the curve at 1/4, 1/2, 3/4 of each
    interval is within tolerance."""
    if not np.isfinite(chord_tol) or chord_tol <= 0:
        raise ValueError(f"chord_tol: must be finite and > 0, got {chord_tol}")
    marks = np.unique(np.concatenate([path.breakpoints_s(), path.corners_s()]))
    u = np.unique(path.u_of_s(marks))
    for _ in range(max_passes):
        a, b = u[:-1], u[1:]
        probe = a[:, None] + (b - a)[:, None] * np.array([0.25, 0.5, 0.75])[None, :]
        xs = path.eval_u(probe.ravel(), 0)[0].reshape((*probe.shape, path.naxes))
        ends = path.eval_u(u, 0)[0] * path.path_scale
        dev = _chord_deviation(xs * path.path_scale, ends[:-1], ends[1:])
        split = dev > chord_tol
        if not np.any(split):
            break
        u = np.sort(np.concatenate([u, 0.5 * (a[split] + b[split])]))
    return path.eval_u(u, 0)[0]


def _chord_deviation(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Max distance of points x (k, p, naxes) from the segments a_k b_k (k, naxes)."""
    ab = (b - a)[:, None, :]
    ax = x - a[:, None, :]
    denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-300)
    t = np.clip(np.sum(ax * ab, axis=-1) / denom, 0.0, 1.0)
    return np.max(np.linalg.norm(ax - t[..., None] * ab, axis=-1), axis=1)
