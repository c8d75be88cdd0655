"""The `linear` fit: straight lines between the points, corners blended within a tolerance
(or exact stops), streamed like `StreamingFit` (PROTOCOL.md `fit = linear`).

Frames and units: points in axis units; u is the cumulative chord length of the kept
points in the path metric (as the other fits), so on a line u = s up to rounding; lengths
and tolerances in path units.

Lines: runs of collinear points (each new point keeps the run's last point within
`MERGE_TOL` of the line from the run's first point, moving forward) are merged into one
line; the merged polyline's vertices are the corners. At a corner with tolerance tol > 0
a quintic blend (`blends`, G2 with its lines) reaching
  l_in = min(tol / deviation_factor, half the incoming line) back along the incoming line,
  l_out = min(tol / deviation_factor, half the outgoing line) along the outgoing one
replaces the corner: it deviates from the polyline by exactly tol unless a short line
limits it (then by less), and never overlaps its neighbours' blends; where both halves
are short, the blends meet with no line between them. A corner is an exact
stop (a tangent break: `Path.corners_s()`, where the planners come to rest) when its
tolerance is 0, when it turns by more than `MAX_BLEND_TURN`, or when its blend would be
shorter than `MIN_BLEND`. The lines between blends are exact lines (deviation 0).

Streaming: each line is split at its midpoint; a blend depends only on its vertex and the
two neighbouring vertices, so once vertex m is known (a point off the line of the run
that follows it has arrived) the path is final up to the midpoint of line m-1 -> m. Points
are processed one by one in stream order, so the final geometry is bit-identical whatever
the chunking. Tail (not final): at most one line, one blend and one half line.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import PPoly

from lookahead.geometry.arclength import Leaves
from lookahead.geometry.base import Path
from lookahead.geometry.blends import (
    blend_coefficients,
    blend_shape,
    deviation_factor,
    turn_angle,
)
from lookahead.geometry.spline_path import SplinePath
from lookahead.geometry.streaming import MIN_STEP, PointStream, _Buffer

#: a point is merged into the current line when the run's last point is within this
#: distance (path units) of the line from the run's first point to it: exact collinear
#: CAM output differs by rounding (~1e-13 mm) only; larger offsets are corners
MERGE_TOL = 1e-10
#: corners turning by more than this (rad) are exact stops: near a reversal the blend's
#: curvature grows without bound (its speed is ~0 anyway), 175 deg = interior angle 5 deg
MAX_BLEND_TURN = math.radians(175.0)
#: blends shorter than this (path units) are exact stops: a blend of 1e-6 mm is crossed at
#: ~0 feed, and the planners' grids would have to resolve it
MIN_BLEND = 1e-6
#: the default corner tolerance (path units), as the machine config's planner.tolerance
DEFAULT_TOLERANCE = 0.05
_DEGREE = 5
_SLIVER = 64.0 * np.finfo(float).eps


def point_tolerances(n: int, tolerance: float | np.ndarray | None, default: float
                     ) -> np.ndarray:
    """One checked tolerance per point of a chunk of `n`: `tolerance` is one value, one per
    point, or None; None and NaN mean `default`."""
    tol = np.full(n, default) if tolerance is None else np.broadcast_to(
        np.asarray(tolerance, dtype=float), (n,))
    tol = np.where(np.isnan(tol), default, tol)
    for t in tol:
        check_tolerance(t)
    return tol


def check_tolerance(value: float, what: str = "tolerance") -> float:
    """`value` as a float; ValueError unless finite and >= 0."""
    out = float(value)
    if not (math.isfinite(out) and out >= 0):
        raise ValueError(f"{what}: must be finite and >= 0, got {value}")
    return out


def joined_spline_path(x: np.ndarray, coef: np.ndarray, leaves: Leaves, end: float,
                       extra: PPoly | None, path_scale: np.ndarray) -> Path:
    """The final pieces (breakpoints `x` without the last one, `end`; coefficients `coef`;
    arc-length `leaves`) followed by `extra` (a PPoly continuing at `end`, or None) as one
    C2 SplinePath in the metric `path_scale`."""
    if extra is not None:
        x = np.concatenate([x, extra.x[:-1]])
        coef = np.concatenate([coef, extra.c], axis=1)
        leaves = Leaves.concat([leaves, SplinePath(extra, path_scale).leaves])
        end = float(extra.x[-1])
    pp = PPoly(coef, np.concatenate([x, [end]]), extrapolate=True)
    return SplinePath(pp, path_scale, continuity=2, leaves=leaves)


class FinalPieces:
    """The final pieces of a streamed spline path (fits `linear`, `smooth`): breakpoints,
    coefficients and arc-length leaves, appended piece runs at a time, and where they end
    (`u_final` in the path's parameter, `s_final` in path units)."""

    def __init__(self, degree: int, naxes: int, path_scale: np.ndarray) -> None:
        self.path_scale = path_scale
        self._x = _Buffer(())  # start u of each final piece
        self._coef = _Buffer((degree + 1, naxes), axis=1)
        self._leaf_start = _Buffer(())
        self._leaf_length = _Buffer(())
        self._leaf_count = _Buffer((), dtype=int)
        self.u_final = 0.0
        self.s_final = 0.0

    def _buffers(self) -> tuple[_Buffer, ...]:
        return (self._x, self._coef, self._leaf_start, self._leaf_length, self._leaf_count)

    def append(self, pp: PPoly) -> None:
        """Append the pieces of `pp` (continuing at `u_final`)."""
        self._x.append(pp.x[:-1])
        self._coef.append(pp.c)
        leaves = SplinePath(pp, self.path_scale).leaves
        self._leaf_start.append(leaves.start)
        self._leaf_length.append(leaves.length)
        self._leaf_count.append(leaves.count)
        self.u_final = float(pp.x[-1])
        # continues the path's own sequential cumsum: bit-identical to its s at the knot
        self.s_final = float(np.cumsum(np.concatenate([[self.s_final], leaves.length]))[-1])

    def path(self, tail: PPoly | None) -> Path:
        """The final pieces followed by `tail` (None: nothing) as one path."""
        leaves = Leaves(self._leaf_start.view(), self._leaf_length.view(),
                        self._leaf_count.view())
        return joined_spline_path(self._x.view(), self._coef.view(), leaves, self.u_final,
                                  tail, self.path_scale)

    def mark(self) -> tuple:
        """The state to go back to with `restore` (for a trial extension)."""
        return tuple(b.size for b in self._buffers()), self.u_final, self.s_final

    def restore(self, mark: tuple) -> None:
        sizes, self.u_final, self.s_final = mark
        for b, size in zip(self._buffers(), sizes, strict=True):
            b.size = size


class TolerancePointStream(PointStream):
    """A point stream whose points carry a corner tolerance (fits `linear`, `smooth`):
    `extend` takes one per chunk or per point; subclasses build geometry in `_finalize`.

    tolerance: the tolerance for chunks that give none (path units, >= 0)."""

    def __init__(self, naxes: int, path_scale: np.ndarray,
                 tolerance: float = DEFAULT_TOLERANCE, min_step: float = MIN_STEP) -> None:
        super().__init__(naxes, path_scale, min_step)
        self.tolerance = check_tolerance(tolerance)
        self._tol = _Buffer(())  # the tolerance of each kept point

    def extend(self, points: np.ndarray, tolerance: float | np.ndarray | None = None) -> None:
        """Append a chunk (n, naxes); `tolerance`: one value, one per point, or None (the
        fit's default; so is NaN). A point's tolerance applies to the corner at that point."""
        tol = point_tolerances(len(np.asarray(points)), tolerance, self.tolerance)
        rows = self._take(points)
        if rows is None:
            return
        self._tol.append(tol[rows])
        self._finalize()

    def _finalize(self) -> None:
        raise NotImplementedError


class LinearFit(TolerancePointStream):
    """`linear` fit of a point stream received in chunks; see the module docstring.

    tolerance: the corner tolerance for chunks that give none (path units, >= 0)."""

    method = "linear"

    def __init__(self, naxes: int, path_scale: np.ndarray,
                 tolerance: float = DEFAULT_TOLERANCE, min_step: float = MIN_STEP) -> None:
        super().__init__(naxes, path_scale, tolerance, min_step)
        self._vert: list[int] = []  # kept-point index of each known vertex
        self._end = -1  # kept-point index of the open run's end (the newest point)
        self._done = 0  # kept points processed
        self._pending: list[tuple[float, float, np.ndarray]] = []  # (u0, u1, coef)
        self._final = FinalPieces(_DEGREE, self.naxes, self.path_scale)
        #: per final corner: (u of the vertex, blend reach back l_in and on l_out along
        #: the lines, in u; 0, 0 = exact stop)
        self.blends: list[tuple[float, float, float]] = []

    # --- geometry ---------------------------------------------------------------------
    def _finalize(self) -> None:
        n = self._u.size
        pts = self._pts.view() * self.path_scale
        for i in range(self._done, n):
            if not self._vert:
                self._vert.append(i)
            elif self._end != self._vert[-1] and not self._merges(pts, i):
                self._vert.append(self._end)
                self._emit_final()
            self._end = i
        self._done = n
        self._flush()

    def _merges(self, pts: np.ndarray, i: int) -> bool:
        """True if point i continues the run from the last vertex through its end."""
        a, e, p = pts[self._vert[-1]], pts[self._end], pts[i]
        d, w = p - a, e - a
        dd = float(d @ d)
        if dd <= 0.0 or float((p - e) @ w) <= 0.0:
            return False
        r = w - (float(w @ d) / dd) * d
        return float(np.sqrt(r @ r)) <= MERGE_TOL

    def _direction(self, ia: int, ib: int) -> np.ndarray:
        """Axis units per u along the line from kept point ia to ib."""
        u, p = self._u.view(), self._pts.view()
        return (p[ib] - p[ia]) / (u[ib] - u[ia])

    def _line(self, ia: int, ib: int, u0: float, u1: float) -> tuple[float, float, np.ndarray]:
        """The line piece over [u0, u1] of the line from kept point ia to ib."""
        d = self._direction(ia, ib)
        coef = np.zeros((_DEGREE + 1, self.naxes))
        coef[-2] = d
        coef[-1] = self._pts.view()[ia] + (u0 - self._u.view()[ia]) * d
        return u0, u1, coef

    def _half_length(self, i0: int, i1: int, i2: int
                     ) -> tuple[float, float, float, float]:
        """(l_in, l_out, c1, c2) of the blend at kept point i1 between i0 and i2 (0, 0: an
        exact stop)."""
        u = self._u.view()
        d1, d2 = self._direction(i0, i1), self._direction(i1, i2)
        m1, m2 = d1 * self.path_scale, d2 * self.path_scale
        s1, s2 = float(np.linalg.norm(m1)), float(np.linalg.norm(m2))
        theta = turn_angle(m1 / s1, m2 / s2)
        tol = float(self._tol.view()[i1])
        stop = (0.0, 0.0, 0.0, 0.0)
        if tol <= 0.0 or theta > MAX_BLEND_TURN or theta <= 0.0:
            return stop
        c1, c2 = blend_shape(theta)
        reach = tol / deviation_factor(theta, c1, c2, max(s1, s2))
        # the halves as measured from the midpoints, so that a blend using a whole half
        # ends exactly where the line's midpoint knot is (no sliver of line between)
        uv = float(u[i1])
        l_in = min(reach, uv - self._mid(i0, i1))
        l_out = min(reach, self._mid(i1, i2) - uv)
        return (l_in, l_out, c1, c2) if min(l_in, l_out) >= MIN_BLEND else stop

    def _corner(self, i0: int, i1: int, i2: int, u_from: float, u_to: float
                ) -> tuple[list[tuple[float, float, np.ndarray]], tuple[float, float]]:
        """Pieces from u_from on line i0 -> i1, through the corner at i1, to u_to on line
        i1 -> i2; and the blend's reach (l_in, l_out; 0, 0: exact stop)."""
        u = self._u.view()
        l_in, l_out, c1, c2 = self._half_length(i0, i1, i2)
        uv = float(u[i1])
        pieces = [self._line(i0, i1, u_from, uv - l_in)]
        if l_in > 0.0:
            coef = blend_coefficients(self._pts.view()[i1], self._direction(i0, i1),
                                      self._direction(i1, i2), l_in, l_out, c1, c2)
            pieces.append((uv - l_in, uv + l_out, coef))
        pieces.append(self._line(i1, i2, uv + l_out, u_to))
        return pieces, (l_in, l_out)

    def _mid(self, ia: int, ib: int) -> float:
        u = self._u.view()
        return 0.5 * (float(u[ia]) + float(u[ib]))

    def _emit_final(self) -> None:
        """Pieces made final by the newest vertex: up to the midpoint of its line."""
        v = self._vert
        if len(v) == 2:
            self._pending.append(self._line(v[0], v[1], 0.0, self._mid(v[0], v[1])))
            return
        i0, i1, i2 = v[-3], v[-2], v[-1]
        pieces, reach = self._corner(i0, i1, i2, self._mid(i0, i1), self._mid(i1, i2))
        self._pending.extend(pieces)
        self.blends.append((float(self._u.view()[i1]), *reach))

    def _tail(self) -> list[tuple[float, float, np.ndarray]]:
        """Pieces after the final ones, the newest point taken as the path's end."""
        v, e = self._vert, self._end
        u_end = float(self._u.view()[e])
        if len(v) == 1:
            return [self._line(v[0], e, 0.0, u_end)]
        pieces, _ = self._corner(v[-2], v[-1], e, self._mid(v[-2], v[-1]), u_end)
        return pieces

    @staticmethod
    def _ppoly(pieces: list[tuple[float, float, np.ndarray]], u_last: float | None = None
               ) -> PPoly | None:
        # pieces shorter than rounding (a blend that used a whole half line) are dropped:
        # the neighbour's polynomial covers them
        keep = [p for p in pieces if p[1] - p[0] > _SLIVER * max(1.0, abs(p[1]))]
        if not keep:
            return None
        x = np.array([p[0] for p in keep] + [keep[-1][1]])
        return PPoly(np.stack([p[2] for p in keep], axis=1), x)

    def _flush(self) -> None:
        """Append the pending final pieces (with their arc-length leaves)."""
        pp = self._ppoly(self._pending)
        self._pending = []
        if pp is None:
            return
        self._final.append(pp)

    # --- output -----------------------------------------------------------------------
    @property
    def final_length(self) -> float:
        """Arc length (path units) up to which the geometry never changes again."""
        return self._final.s_final

    def path(self) -> Path:
        """The best current geometry (>= 2 kept points); identical to the final geometry
        on [0, final_length]."""
        if self._path is None:
            if self._u.size < 2:
                raise ValueError("points: need at least 2 distinct points for a path")
            self._path = self._assemble([] if self._finished else self._tail())
        return self._path

    def _assemble(self, tail: list[tuple[float, float, np.ndarray]]) -> Path:
        """The final pieces followed by `tail` as one path."""
        return self._final.path(self._ppoly(tail))

    def _append_points(self, points: np.ndarray, u: np.ndarray, tol: np.ndarray) -> None:
        """Append kept points with given u (increasing, past the last) and tolerances, and
        process them (for fits that feed this one with their own vertices)."""
        self._u.append(u)
        self._pts.append(points)
        self._tol.append(tol)
        self._path = None
        self._finalize()

    def path_with(self, points: np.ndarray, u: np.ndarray, tol: np.ndarray) -> Path:
        """The path as if `points` (with their u, tolerances) were appended next, without
        appending them (the fit's state is restored)."""
        saved = (len(self._vert), self._end, self._done, len(self.blends), self._u.size)
        final = self._final.mark()
        self._u.append(u)
        self._pts.append(points)
        self._tol.append(tol)
        n = self._u.size
        pts = self._pts.view() * self.path_scale
        for i in range(self._done, n):
            if self._end != self._vert[-1] and not self._merges(pts, i):
                self._vert.append(self._end)
                self._emit_final()
            self._end = i
        path = self._assemble([*self._pending, *self._tail()])
        del self._vert[saved[0]:]
        self._end, self._done = saved[1], saved[2]
        del self.blends[saved[3]:]
        self._pending = []
        for b in (self._u, self._pts, self._tol):
            b.size = saved[4]
        self._final.restore(final)
        return path

    def finish(self) -> Path:
        """End of stream: everything becomes final. Returns the complete path."""
        if not self._finished:
            if self._u.size < 2:
                raise ValueError("points: need at least 2 distinct points for a path")
            tail = self._tail()
            if len(self._vert) >= 2:
                reach = self._half_length(self._vert[-2], self._vert[-1], self._end)[:2]
                self.blends.append((float(self._u.view()[self._vert[-1]]), *reach))
            self._pending.extend(tail)
            self._flush()
            self._finished = True
            self._path = None
        return self.path()

    def vertices(self) -> np.ndarray:
        """The merged polyline's vertices (k, naxes) in axis units, the newest point last."""
        idx = [*self._vert, self._end] if self._end != self._vert[-1] else list(self._vert)
        return self._pts.view()[idx].copy()
