"""The `smooth` fit for dense CAM output (PROTOCOL.md `fit = smooth`): the point stream is
simplified within a share of the tolerance, and the simplified polyline becomes the control
polygon of a cubic B-spline within the rest (`control_spline`: plain control points on
dense arcs, corner groups on lines elsewhere). The curve is G2 (curvature continuous) and
made of few pieces: its feed is set by the part's curvature and the tolerance, not by the
number of points or their quantization noise; long lines stay exact lines.

Frames and units: points in axis units; u is the cumulative chord length of the original
points in the path metric (as every fit: a segment's end in chord u maps to s); lengths and
tolerances in path units.

Bound: every point of the curve is within tol of the original polyline: the spline stays
within (1 - SIMPLIFY_SHARE) tol of the simplified polyline, and each simplified chord a->b
is within SIMPLIFY_SHARE tol of the original points a..b (every original point between
them is within that distance of the chord segment, so the original polyline crosses each
chord point's normal inside that band: the chord lies within it of the polyline).

Simplification (streamed): from the last kept vertex a, the newest point e extends the
chord while every point between a and e is within the share of its own tolerance of the
segment a->e, for at most `MAX_RUN` points; otherwise e's predecessor becomes a vertex.
Decided point by point in stream order: bit-identical whatever the chunking.
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.geometry.control_spline import ControlSpline
from lookahead.geometry.polyline import DEFAULT_TOLERANCE, MERGE_TOL, TolerancePointStream
from lookahead.geometry.streaming import MIN_STEP

#: share of the tolerance taken by the simplification (the spline gets the rest): more
#: gives longer chords (sagitta L^2 / (8 R) ~ share * tol) but the quintic inside them
#: needs L^2 / (4 R) ~ 2 share * tol of the rest to keep dense arcs plain (curvature
#: without ripple, `control_spline.PLAIN_SHARE`): 0.2 leaves 0.8 for it
SIMPLIFY_SHARE = 0.2
#: a chord covers at most this many points (bounds the O(run) check per point)
MAX_RUN = 256


class SmoothFit(TolerancePointStream):
    """`smooth` fit of a point stream received in chunks; see the module docstring."""

    method = "smooth"

    def __init__(self, naxes: int, path_scale: np.ndarray,
                 tolerance: float = DEFAULT_TOLERANCE, min_step: float = MIN_STEP) -> None:
        super().__init__(naxes, path_scale, tolerance, min_step)
        self._inner = ControlSpline(naxes, self.path_scale)
        self._anchor = -1  # kept-point index of the last simplified vertex
        self._done = 0

    @property
    def kinds(self) -> list[str]:
        """Per decided simplified vertex: "plain", "group" or "stop" (`ControlSpline`)."""
        return self._inner.kinds

    def _finalize(self) -> None:
        n = self._u.size
        pts = self._pts.view() * self.path_scale
        tol = self._tol.view()
        keep: list[int] = []
        for e in range(self._done, n):
            if self._anchor < 0:
                self._anchor = e
                keep.append(e)
            elif e - self._anchor > 1 and not self._chord_holds(pts, tol, e):
                self._anchor = e - 1
                keep.append(e - 1)
        self._done = n
        pts_axis, u = self._pts.view(), self._u.view()
        for i in keep:
            self._inner.add(pts_axis[i], float(u[i]), (1.0 - SIMPLIFY_SHARE) * float(tol[i]))
        self._inner.flush()

    def _chord_holds(self, pts: np.ndarray, tol: np.ndarray, e: int) -> bool:
        """True if the points strictly between the anchor and e are within their share of
        the tolerance of the segment anchor -> e (and the chord is not too long)."""
        a = self._anchor
        if e - a > MAX_RUN:
            return False
        pa, d = pts[a], pts[e] - pts[a]
        rel = pts[a + 1 : e] - pa
        t = np.clip((rel @ d) / max(float(d @ d), 1e-300), 0.0, 1.0)
        dist = np.linalg.norm(rel - t[:, None] * d, axis=1)
        return bool(np.all(dist <= np.maximum(SIMPLIFY_SHARE * tol[a + 1 : e], MERGE_TOL)))

    # --- output -----------------------------------------------------------------------
    @property
    def final_length(self) -> float:
        return self._inner.final_length

    def _open_end(self) -> int | None:
        """Kept-point index of the newest point when it is not yet a vertex."""
        e = self._u.size - 1
        return e if e > self._anchor else None

    def path(self) -> Path:
        """The best current geometry (>= 2 kept points); identical to the final geometry
        on [0, final_length]."""
        if self._path is None:
            if self._u.size < 2:
                raise ValueError("points: need at least 2 distinct points for a path")
            e = self._open_end()
            if self._finished:
                self._path = self._inner.finish()
            elif e is None:
                self._path = self._inner.path_with(None, 0.0, 0.0)
            else:
                self._path = self._inner.path_with(
                    self._pts.view()[e], float(self._u.view()[e]),
                    (1.0 - SIMPLIFY_SHARE) * float(self._tol.view()[e]))
        return self._path

    def finish(self) -> Path:
        """End of stream: everything becomes final. Returns the complete path."""
        if not self._finished:
            if self._u.size < 2:
                raise ValueError("points: need at least 2 distinct points for a path")
            e = self._open_end()
            if e is not None:
                self._inner.add(self._pts.view()[e], float(self._u.view()[e]),
                                (1.0 - SIMPLIFY_SHARE) * float(self._tol.view()[e]))
                self._anchor = e
            self._inner.finish()
            self._finished = True
            self._path = None
        return self.path()
