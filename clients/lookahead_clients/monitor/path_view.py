"""The programmed path of one job as the monitor sees it on `NS/segments`, and where the
machine is along it.

The path is kept as a polyline in axis space (axis units): a `points` segment contributes
its points, a `bspline` / `nurbs` segment its curve sampled at uniform parameter steps.
Progress is measured in the machine's path metric (each axis scaled by `path_scale`): the
commanded position is projected onto the polyline, searching forward from the last match
(so a path that crosses itself is followed in order), and the arc length up to that point
is divided by the polyline's length. This is a measurement on the programmed geometry, not
the planner's fitted curve: for `points` jobs the two differ by the fit's deviation from the
points' polyline (within the tolerance for `linear`/`smooth`, a small fraction of the chord
for `cubic`/`pchip`).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline

from lookahead.protocol import Segment

#: points of the path sent to a browser for drawing (a uniform stride of the polyline)
DRAW_POINTS = 4000
#: curve samples per control point of a bspline/nurbs segment (at least CURVE_MIN)
CURVE_PER_CTRL, CURVE_MIN = 8, 32
#: a located point farther than this fraction of the path's extent from the window ahead
#: means the monitor lost the machine (it joined late): the whole path is searched
LOST_FRACTION = 0.05


def segment_points(seg: Segment) -> np.ndarray:
    """The polyline (n, naxes) one segment contributes (axis units)."""
    if seg.kind == "points":
        assert seg.points is not None
        return np.asarray(seg.points, dtype=float)
    assert seg.ctrl is not None and seg.knots is not None and seg.degree is not None
    ctrl = np.asarray(seg.ctrl, dtype=float)
    knots = np.asarray(seg.knots, dtype=float)
    u = np.linspace(knots[0], knots[-1], max(CURVE_MIN, CURVE_PER_CTRL * len(ctrl)))
    if seg.kind == "nurbs":
        assert seg.weights is not None
        w = np.asarray(seg.weights, dtype=float)
        num = BSpline(knots, ctrl * w[:, None], seg.degree)(u)
        den = BSpline(knots, w, seg.degree)(u)
        return num / den[:, None]
    return BSpline(knots, ctrl, seg.degree)(u)


class ProgrammedPath:
    """One job's segments (by seq) and the polyline of the contiguous run from seq 0."""

    def __init__(self, job: str, path_scale) -> None:
        self.job = job
        self.scale = np.asarray(path_scale, dtype=float)
        self.pieces: dict[int, np.ndarray] = {}
        self.last_seq: int | None = None
        self.version = 0  # increases whenever the polyline changes
        self._poly = np.empty((0, self.scale.size))
        self._cum = np.zeros(0)  # arc length (path metric) at each polyline vertex
        self._s = 0.0  # last located arc length
        self._seq_run = 0  # segments 0.._seq_run-1 are in the polyline
        self._extent = 1.0  # diagonal of the polyline's bounding box (path metric)

    def add(self, seg: Segment) -> None:
        """Take a segment (a repeat of a seq already held is ignored)."""
        if seg.seq in self.pieces:
            return
        self.pieces[seg.seq] = segment_points(seg)
        if seg.last:
            self.last_seq = seg.seq
        if seg.seq == self._seq_run:
            self._extend()

    def _extend(self) -> None:
        parts = [self._poly]
        while self._seq_run in self.pieces:
            parts.append(self.pieces[self._seq_run])
            self._seq_run += 1
        self._poly = np.vstack(parts)
        d = np.linalg.norm(np.diff(self._poly, axis=0) * self.scale, axis=1)
        self._cum = np.r_[0.0, np.cumsum(d)]
        scaled = self._poly * self.scale
        self._extent = float(np.linalg.norm(scaled.max(axis=0) - scaled.min(axis=0))) or 1.0
        self.version += 1

    @property
    def complete(self) -> bool:
        """True once every segment 0..last is held."""
        return self.last_seq is not None and self._seq_run > self.last_seq

    @property
    def length(self) -> float:
        """Polyline length in the path metric (path units)."""
        return float(self._cum[-1]) if self._cum.size else 0.0

    @property
    def segments(self) -> int:
        return len(self.pieces)

    def drawing(self, max_points: int = DRAW_POINTS) -> list[list[float]]:
        """The polyline decimated to at most `max_points` vertices (first and last kept)."""
        n = self._poly.shape[0]
        if n <= max_points:
            idx = np.arange(n)
        else:
            idx = np.unique(np.r_[np.linspace(0, n - 1, max_points).astype(int), n - 1])
        return np.round(self._poly[idx], 5).tolist()

    def locate(self, pos: np.ndarray) -> float | None:
        """Arc length (path units) of the commanded position `pos` (naxes,) along the
        polyline, searched forward from the last located point; None without a polyline.

        The window ahead covers the chord to `pos` four times plus 64 vertices, so a
        located point never jumps to a later pass of a self-crossing path."""
        if self._poly.shape[0] < 2:
            return None
        p = np.asarray(pos, dtype=float) * self.scale
        here = self._point_at(self._s)
        reach = 4.0 * float(np.linalg.norm(p - here)) + 1e-9
        lo = max(int(np.searchsorted(self._cum, self._s, side="right")) - 2, 0)
        hi = min(int(np.searchsorted(self._cum, self._s + reach)) + 64, self._cum.size - 1)
        s, dist = self._nearest(p, lo, hi)
        if dist <= LOST_FRACTION * self._extent:
            self._s = max(s, self._s)
        elif lo > 0 or hi < self._cum.size - 1:  # lost (e.g. joined late): search it all
            self._s, _ = self._nearest(p, 0, self._cum.size - 1)
        else:
            self._s = s
        return self._s

    def _point_at(self, s: float) -> np.ndarray:
        i = int(np.clip(np.searchsorted(self._cum, s, side="right") - 1, 0,
                        self._cum.size - 2))
        seg = self._cum[i + 1] - self._cum[i]
        t = 0.0 if seg <= 0 else min(max((s - self._cum[i]) / seg, 0.0), 1.0)
        return (self._poly[i] + t * (self._poly[i + 1] - self._poly[i])) * self.scale

    def _nearest(self, p: np.ndarray, lo: int, hi: int) -> tuple[float, float]:
        """(arc length, distance) of the point of vertices lo..hi nearest to p (scaled)."""
        a = self._poly[lo:hi] * self.scale
        b = self._poly[lo + 1:hi + 1] * self.scale
        ab = b - a
        denom = np.einsum("ij,ij->i", ab, ab)
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(denom > 0, denom, 1.0), 0, 1)
        dist = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
        i = int(np.argmin(dist))
        s = self._cum[lo + i] + t[i] * (self._cum[lo + i + 1] - self._cum[lo + i])
        return float(s), float(dist[i])

    def progress(self, s: float | None) -> float | None:
        """Fraction 0..1 of the programmed length at arc length `s`; None unless the whole
        path (seq 0..last) is held."""
        if s is None or not self.complete or self.length <= 0:
            return None
        return min(max(s / self.length, 0.0), 1.0)
