"""A streamed cubic B-spline over a control polygon built from polyline vertices: the curve
of the `smooth` fit.

Frames and units: vertices in axis units; c is each vertex's cumulative chord length of
the original points in the path metric (the fits' common parameter u); lengths and
tolerances in path units.

Control polygon: a vertex with a small turn between similar lengths is a control point
itself ("plain": on a dense arc the curve then has the arc's own, nearly constant,
curvature, which no corner blend gives); any other vertex becomes the group
  V - 2 b1 D1, V - b1 D1, V, V + b2 D2, V + 2 b2 D2
on its two lines (D per unit of c), b_i = min(6 tol / (sin(theta) sigma), L_i / 4.5); the
path's ends start and stop on their lines the same way. Knots are uniform (in the
control-point index), clamped at the path's ends and at exact stops (tolerance 0 or a
near-reversal), where one spline run ends at the vertex and the next starts there.

Deviation: for a group, the control points' distances from the incoming line are 0 up to
V and increase after it (variation diminishing: so does the curve's), the outgoing line's
mirror them, so the curve is furthest from the two lines where the two distances are
equal: at most max(b1, b2) sin(theta) sigma / 6 (exactly that at V's knot when b1 = b2).
A plain vertex between lengths L1, L2 keeps the curve within about max(L1, L2)
sin(theta) sigma / 6 of its lines, so it is plain only where that is within
`PLAIN_SHARE` of the tolerance.

Parameter: each uniform knot span is mapped linearly onto a stretch of c (the averages of
its control points' c), so the path's u is the chord u of the points it came from (the
curve is G2: x_s and x_ss are continuous in arc length).

Streaming: a vertex's control points are final once the next vertex is known; a knot span
once the control points 6 ahead are final (its knots and control points no longer change).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline, PPoly

from lookahead.geometry.base import Path
from lookahead.geometry.blends import turn_angle
from lookahead.geometry.piecewise import ppoly_from_bspline
from lookahead.geometry.polyline import MAX_BLEND_TURN, MIN_BLEND, FinalPieces
from lookahead.geometry.streaming import _Buffer

#: a vertex turning by at most this (rad) between lengths within PLAIN_RATIO of each other
#: may be a plain control point
PLAIN_TURN = math.radians(20.0)
PLAIN_RATIO = 2.0
#: a plain vertex's estimated deviation max(L1, L2) sin(theta) / 6 may use this share of
#: the tolerance (the estimate is exact at the knot, the curve between knots stays closer
#: on arcs; 0.8 kept every random polyline of tests/test_geometry_smooth_fit.py in)
PLAIN_SHARE = 0.8
#: group offsets are at most this fraction of their line (two groups never cross)
#: a group's points span at most this fraction of each of its lines (two never cross)
GROUP_SPAN = 2.0 / 4.5
#: the spline's degree: 5 (C4) rather than 3: the LP planner's sampled check failed by
#: ~1 % on the cubic's jumps of d3x/ds3 at every knot of a dense circle
DEGREE = 5
_DEG = DEGREE
#: distance from the lines of a symmetric group's curve at V, per unit of b sin(theta):
#: the uniform B-spline's weights at a knot ((1, 4, 1) / 6; (1, 26, 66, 26, 1) / 120) on
#: the points at b, 2b from V
CORNER_FACTOR = {3: 1.0 / 6.0, 5: 28.0 / 120.0}[DEGREE]
#: distance of the curve at a plain vertex from it, per unit of L sin(theta) on a regular
#: polygon (L^2 / (6 R) for the cubic, L^2 / (4 R) for the quintic)
PLAIN_FACTOR = {3: 1.0 / 6.0, 5: 1.0 / 4.0}[DEGREE]


class ControlSpline:
    """Vertices in, a G2 cubic B-spline path out; see the module docstring."""

    def __init__(self, naxes: int, path_scale: np.ndarray) -> None:
        self.naxes = naxes
        self.path_scale = np.asarray(path_scale, dtype=float).reshape(-1)
        self._w = _Buffer((naxes,))  # vertices
        self._c = _Buffer(())  # their chord u
        self._tol = _Buffer(())
        self._run_q = _Buffer((naxes,))  # control points of the current run
        self._run_c = _Buffer(())  # their chord u
        self._run_spans = 0  # final spans emitted of the current run
        self._final = FinalPieces(_DEG, naxes, self.path_scale)
        self._finished = False
        #: per decided vertex: "plain", "group" or "stop"
        self.kinds: list[str] = []

    # --- vertices -> control points -----------------------------------------------------
    def add(self, point: np.ndarray, c: float, tol: float) -> None:
        """Append the next vertex (final); `flush` then emits the final pieces."""
        self._w.append(np.asarray(point, dtype=float)[None, :])
        self._c.append(np.array([c]))
        self._tol.append(np.array([tol]))
        n = self._w.size
        if n == 2:
            self._run_start(0)
        elif n >= 3:
            self._decide(n - 2)

    def _line(self, i: int, j: int) -> tuple[np.ndarray, float, float]:
        """(direction per unit c, metric length per unit c, c length) of line i -> j."""
        w, c = self._w.view(), self._c.view()
        dc = float(c[j] - c[i])
        d = (w[j] - w[i]) / dc
        return d, float(np.linalg.norm(d * self.path_scale)), dc

    def _push(self, points: list[np.ndarray], cs: list[float]) -> None:
        self._run_q.append(np.array(points))
        self._run_c.append(np.array(cs))

    def _run_start(self, i: int) -> None:
        """Control points starting a run at vertex i on the line to i + 1."""
        w, c = self._w.view(), self._c.view()
        d, _, dc = self._line(i, i + 1)
        b = GROUP_SPAN * dc / (_DEG - 1)
        k = np.arange(_DEG, dtype=float)
        self._push(list(w[i] + (k * b)[:, None] * d), list(float(c[i]) + k * b))

    def _run_end(self, j: int) -> None:
        """Control points ending a run at vertex j, coming from j - 1."""
        w, c = self._w.view(), self._c.view()
        d, _, dc = self._line(j - 1, j)
        b = GROUP_SPAN * dc / (_DEG - 1)
        k = np.arange(_DEG - 1, -1, -1, dtype=float)
        self._push(list(w[j] - (k * b)[:, None] * d), list(float(c[j]) - k * b))

    def _decide(self, j: int) -> None:
        """Control points of vertex j (its neighbours j - 1 and j + 1 are known)."""
        w, c = self._w.view(), self._c.view()
        d1, s1, dc1 = self._line(j - 1, j)
        d2, s2, dc2 = self._line(j, j + 1)
        theta = turn_angle(d1 * self.path_scale / s1, d2 * self.path_scale / s2)
        tol = float(self._tol.view()[j])
        sigma = max(s1, s2)
        sin = math.sin(theta)
        if tol <= 0.0 or theta > MAX_BLEND_TURN:
            self._stop(j)
            return
        len1, len2 = s1 * dc1, s2 * dc2
        if (theta <= PLAIN_TURN and max(len1, len2) <= PLAIN_RATIO * min(len1, len2)
                and max(len1, len2) * sin * PLAIN_FACTOR <= PLAIN_SHARE * tol):
            self.kinds.append("plain")
            self._push([w[j]], [float(c[j])])
            return
        reach = tol / (CORNER_FACTOR * sin * sigma) if sin > 0 else math.inf
        span = GROUP_SPAN / (_DEG - 1)
        b1, b2 = min(reach, span * dc1), min(reach, span * dc2)
        if min(b1 * s1, b2 * s2) < MIN_BLEND:
            self._stop(j)
            return
        self.kinds.append("group")
        cj = float(c[j])
        k = np.arange(1, _DEG, dtype=float)
        before = [w[j] - kk * b1 * d1 for kk in k[::-1]]
        after = [w[j] + kk * b2 * d2 for kk in k]
        self._push([*before, w[j], *after],
                   [*(cj - k[::-1] * b1), cj, *(cj + k * b2)])

    def _stop(self, j: int) -> None:
        """An exact stop at vertex j: the run ends there (all final), a new one starts."""
        self.kinds.append("stop")
        self._run_end(j)
        self._emit_spans(self._run_spans, self._nspans(complete=True), complete=True)
        # new buffers, not emptied ones: `path_with` restores the old run afterwards
        self._run_q, self._run_c = _Buffer((self.naxes,)), _Buffer(())
        self._run_spans = 0
        self._run_start(j)

    # --- control points -> pieces ---------------------------------------------------------
    def _nspans(self, complete: bool) -> int:
        """Spans of the current run that are final (all of them when complete)."""
        k = self._run_q.size
        return k - _DEG if complete else max(k - 2 * _DEG, 0)

    def _pieces(self, q: np.ndarray, cq: np.ndarray, i0: int, i1: int, complete: bool
                ) -> PPoly:
        """PPoly (in chord u) of spans i0..i1-1 of a run with control points q, cq."""
        m = len(q) - 1  # clamped: knots t_k = clip(k - p, 0, m - p + 1)
        hi = m - _DEG + 1 if complete else np.inf
        t = np.clip(np.arange(i0, i1 + 2 * _DEG + 1) - _DEG, 0, hi).astype(float)
        spline = BSpline(t, q[i0 : i1 + _DEG], _DEG)
        pp = ppoly_from_bspline(spline)
        a = self._span_chords(cq, i0, i1 + 1, complete)
        width = np.diff(a)
        power = np.arange(_DEG, -1, -1, dtype=float)  # PPoly rows: highest power first
        coef = pp.c / width[None, :, None] ** power[:, None, None]
        return PPoly(coef, a)

    @staticmethod
    def _span_chords(cq: np.ndarray, i0: int, i1: int, complete: bool) -> np.ndarray:
        """Chord u of knot values i0..i1-1 (uniform knot i -> mean c of control points
        i .. i + p - 1; the run's ends at its end control points)."""
        i = np.arange(i0, i1)
        last = len(cq) - 1
        a = np.mean([cq[np.minimum(i + k, last)] for k in range(_DEG)], axis=0)
        a = np.where(i == 0, cq[0], a)
        if complete:
            a = np.where(i == len(cq) - _DEG, cq[-1], a)
        return a

    def _emit_spans(self, i0: int, i1: int, complete: bool) -> None:
        if i1 <= i0:
            return
        self._final.append(self._pieces(self._run_q.view(), self._run_c.view(), i0, i1,
                                        complete))
        self._run_spans = i1

    def flush(self) -> None:
        """Emit the pieces made final by the vertices added since the last call."""
        self._emit_spans(self._run_spans, self._nspans(complete=False), complete=False)

    # --- output -----------------------------------------------------------------------
    @property
    def final_length(self) -> float:
        return self._final.s_final

    def _assemble(self, tail: PPoly | None) -> Path:
        return self._final.path(tail)

    def path_with(self, point: np.ndarray | None, c: float, tol: float) -> Path:
        """The path as if `point` were the last vertex (None: the current last vertex is
        the end), the state left unchanged."""
        saved = [(b, b.size) for b in (self._w, self._c, self._tol, self._run_q, self._run_c)]
        final = self._final.mark()
        run = (self._run_q, self._run_c)
        scalars = (self._run_spans, len(self.kinds))
        try:
            if point is not None:
                self._w.append(np.asarray(point, dtype=float)[None, :])
                self._c.append(np.array([c]))
                self._tol.append(np.array([tol]))
                n = self._w.size
                if n == 2:
                    self._run_start(0)
                else:
                    self._decide(n - 2)
            self._run_end(self._w.size - 1)
            k = self._run_q.size
            tail = self._pieces(self._run_q.view(), self._run_c.view(), self._run_spans,
                                k - _DEG, complete=True) if k - _DEG > self._run_spans else None
            return self._assemble(tail)
        finally:
            for b, size in saved:
                b.size = size
            self._final.restore(final)
            self._run_q, self._run_c = run
            self._run_spans = scalars[0]
            del self.kinds[scalars[1]:]

    def finish(self) -> Path:
        """The last vertex ends the path; everything final."""
        if not self._finished:
            self._run_end(self._w.size - 1)
            self._emit_spans(self._run_spans, self._nspans(complete=True), complete=True)
            self._finished = True
        return self._assemble(None)
