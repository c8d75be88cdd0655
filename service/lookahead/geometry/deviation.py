"""Distance from the programmed polyline: an independent measure of how far a path (or the
sampled setpoints of a planned profile) leaves the points it was fitted to.

Frames and units: positions in axis units; distances in the path metric
||path_scale * dx|| (path units). The polyline is the straight segments between
consecutive programmed points; nothing here knows how a fit was built.

`polyline_distance` is exact (nearest point on every candidate segment): long segments are
cut into pieces of at most `h` for the search only, a k-d tree (scipy cKDTree) over the
pieces' midpoints finds the candidates (any piece holding the nearest point has its
midpoint within d_nearest_midpoint + h/2), and the distances are computed to the pieces.
`path_deviation` samples a path densely in u and refines every local maximum by golden
section, so its maximum is the curve's true one to ~1e-12, not the sampling's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from lookahead.geometry.base import Path

#: nearest midpoints asked for per query (more only where the ball needs more)
_K = 16
#: positions measured per batch: the temporaries are (batch, k, naxes) floats, so 3M
#: samples at once (a 100k-line program's `lookahead plan`) peaked at 8.9 GB resident;
#: 20000 keeps them near 8 MB at k = 16 (trades nothing: each position is measured alone)
_BATCH = 20_000
_GOLDEN = 0.5 * (np.sqrt(5.0) - 1.0)


def segment_distance(x: np.ndarray, a: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """Distances of points x from the segments a -> a + ab (metric units; arrays that
    broadcast, coordinates on the last axis)."""
    denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-300)
    t = np.clip(np.sum((x - a) * ab, axis=-1) / denom, 0.0, 1.0)
    return np.linalg.norm(x - (a + t[..., None] * ab), axis=-1)


class PolylineDistance:
    """Distance (path units) of positions from the polyline through `points` (n, naxes)."""

    def __init__(self, points: np.ndarray, path_scale: np.ndarray, max_pieces: int = 400_000
                 ) -> None:
        self.path_scale = np.asarray(path_scale, dtype=float).reshape(-1)
        p = np.asarray(points, dtype=float).reshape(-1, self.path_scale.size) * self.path_scale
        if len(p) == 1:
            p = np.vstack([p, p])
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        total = float(seg.sum())
        positive = seg[seg > 0]
        h = float(np.median(positive)) if positive.size else 1.0
        h = max(h, total / max_pieces, 1e-12)
        cuts = np.maximum(1, np.ceil(seg / h)).astype(int)
        owner = np.repeat(np.arange(seg.size), cuts)
        k = np.arange(owner.size) - np.repeat(np.cumsum(cuts) - cuts, cuts)
        frac0 = k / cuts[owner]
        frac1 = (k + 1) / cuts[owner]
        d = p[1:] - p[:-1]
        self._a = p[:-1][owner] + frac0[:, None] * d[owner]
        self._b = p[:-1][owner] + frac1[:, None] * d[owner]
        self._half = 0.5 * float(np.max(np.linalg.norm(self._b - self._a, axis=1)))
        self._tree = cKDTree(0.5 * (self._a + self._b))

    def _to_pieces(self, x: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Distances (m, k) of metric positions x (m, naxes) to pieces idx (m, k)."""
        a = self._a[idx]
        return segment_distance(x[:, None, :], a, self._b[idx] - a)

    def __call__(self, positions: np.ndarray) -> np.ndarray:
        """(m,) distances of positions (m, naxes), axis units, from the polyline."""
        x = np.atleast_2d(np.asarray(positions, dtype=float)) * self.path_scale
        if len(x) <= _BATCH:
            return self._distances(x)
        return np.concatenate([self._distances(x[i:i + _BATCH])
                               for i in range(0, len(x), _BATCH)])

    def _distances(self, x: np.ndarray) -> np.ndarray:
        """(m,) distances of metric positions x (m, naxes) from the polyline."""
        out = np.empty(len(x))
        todo = np.arange(len(x))
        k = _K
        while todo.size:
            k = min(k, self._tree.n)
            dist, idx = self._tree.query(x[todo], k=k)
            dist, idx = dist.reshape(todo.size, k), idx.reshape(todo.size, k)
            out[todo] = np.min(self._to_pieces(x[todo], idx), axis=1)
            # the k found pieces hold the nearest one unless a piece further than the
            # k-th midpoint could still be nearer: those ask for 8 times as many
            if k == self._tree.n:
                break
            todo = todo[dist[:, -1] <= dist[:, 0] + self._half]
            k *= 8
        return out


def polyline_distance(positions: np.ndarray, points: np.ndarray, path_scale: np.ndarray
                      ) -> np.ndarray:
    """(m,) distances (path units) of positions (m, naxes) from the polyline of points."""
    return PolylineDistance(points, path_scale)(positions)


def _sample_u(path: Path, per_interval: int) -> np.ndarray:
    bps = getattr(path, "breakpoints_u", None)
    knots = bps() if callable(bps) else path.u_of_s(path.breakpoints_s())
    knots = np.unique(np.concatenate([knots, path.u_range]))
    frac = np.arange(per_interval) / per_interval
    u = (knots[:-1, None] + np.diff(knots)[:, None] * frac[None, :]).ravel()
    return np.concatenate([u, knots[-1:]])


@dataclass(frozen=True)
class Deviation:
    """A path's distance from its polyline: u (m,) where it was measured, dev (m,)
    (path units), and the largest one `max` at u_max / s_max."""

    u: np.ndarray
    dev: np.ndarray
    max: float
    u_max: float
    s_max: float


def path_deviation(path: Path, points: np.ndarray, per_interval: int = 32,
                   refine_above: float = 0.0) -> Deviation:
    """Distance of `path` from the polyline of `points`: sampled `per_interval` times per
    knot interval, every local maximum above `refine_above` refined by golden section."""
    measure = PolylineDistance(points, path.path_scale)
    u = _sample_u(path, per_interval)
    dev = measure(path.eval_u(u, 0)[0])
    inner = np.flatnonzero((dev[1:-1] >= dev[:-2]) & (dev[1:-1] >= dev[2:])
                           & (dev[1:-1] > refine_above)) + 1
    u_ref, d_ref = np.empty(0), np.empty(0)
    if inner.size:
        a, b = u[inner - 1].copy(), u[inner + 1].copy()

        def f(v: np.ndarray) -> np.ndarray:
            return measure(path.eval_u(v, 0)[0])

        c, d = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
        fc, fd = f(c), f(d)
        for _ in range(80):
            left = fc > fd  # the maximum is in [a, d], else in [c, b]
            b = np.where(left, d, b)
            a = np.where(left, a, c)
            new_c = np.where(left, b - _GOLDEN * (b - a), d)
            new_d = np.where(left, c, a + _GOLDEN * (b - a))
            fp = f(np.where(left, new_c, new_d))
            fc, fd = np.where(left, fp, fd), np.where(left, fc, fp)
            c, d = new_c, new_d
            if np.all(b - a <= 1e-14 * np.maximum(1.0, np.abs(a))):
                break
        u_ref = 0.5 * (a + b)
        d_ref = f(u_ref)
    all_u = np.concatenate([u, u_ref])
    all_d = np.concatenate([dev, d_ref])
    order = np.argsort(all_u, kind="stable")
    all_u, all_d = all_u[order], all_d[order]
    i = int(np.argmax(all_d))
    return Deviation(all_u, all_d, float(all_d[i]), float(all_u[i]),
                     float(path.s_of_u(np.array([all_u[i]]))[0]))


#: a chord-distance bound below tolerance * (1 - this) is certainly inside the tolerance
#: (the exact measure differs from it by rounding only, ~1e-15 relative)
_BOUND_REL = 1e-9


def _own_chord_distance(x: np.ndarray, points: np.ndarray, path_scale: np.ndarray, k0: int,
                        k1: int, per: int, lo: int, hi: int) -> np.ndarray:
    """(m,) distances (path units) of positions x (m, naxes; `per` consecutive samples
    in each knot interval k0..k1-1) from the chord points[i] -> points[i+1] of their own
    interval i: an upper bound on the distance from the polyline of points[lo:hi], which
    holds that chord (+inf where it does not: no bound)."""
    scale = np.asarray(path_scale, dtype=float).reshape(-1)
    nint = k1 - k0
    out = np.full((nint, per), np.inf)
    i1 = min(k1, hi - 1)  # intervals k0..i1-1 have both chord ends in points[lo:hi]
    n = i1 - k0
    if n <= 0 or k0 < lo:
        return out.ravel()
    pts = np.asarray(points[k0:i1 + 1], dtype=float) * scale
    a, ab = pts[:-1, None, :], (pts[1:] - pts[:-1])[:, None, :]
    out[:n] = segment_distance(x.reshape(nint, per, -1)[:n] * scale, a, ab)
    return out.ravel()


@dataclass(frozen=True)
class Excursion:
    """A stretch [s_start, s_end] (path units) where a path is more than the tolerance
    from its polyline; `dev` the largest distance there, at `s_max`."""

    s_start: float
    s_end: float
    dev: float
    s_max: float


def excursions(path: Path, points: np.ndarray, tolerance: float, per_interval: int = 32
               ) -> list[Excursion]:
    """Where `path` leaves the polyline of `points` by more than `tolerance`."""
    d = path_deviation(path, points, per_interval, refine_above=tolerance)
    return excursion_runs(path, d.u, d.dev, tolerance)


def excursion_runs(path: Path, u: np.ndarray, dev: np.ndarray, tolerance: float
                   ) -> list[Excursion]:
    """The runs of consecutive samples (at parameters u, increasing) whose distance `dev`
    from the polyline exceeds `tolerance`, each as an Excursion with its largest one."""
    over = dev > tolerance
    if not np.any(over):
        return []
    s = path.s_of_u(u)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], over.astype(int), [0]])))
    out = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        j = a + int(np.argmax(dev[a:b]))
        out.append(Excursion(float(s[a]), float(s[b - 1]), float(dev[j]), float(s[j])))
    return out


def interval_excursions(path: Path, points: np.ndarray, k0: int, k1: int, tolerance: float,
                        per_interval: int = 16, context: int = 4) -> list[Excursion]:
    """Excursions beyond `tolerance` of knot intervals k0..k1-1 of an interpolating fit
    (knots at `points`, in order), measured against the polyline of the points from
    `context` before k0 to `context` after k1 (a local, streaming check: the distance to
    that stretch of the polyline, >= the distance to all of it)."""
    knots = path.breakpoints_u()
    lo, hi = max(k0 - context, 0), min(k1 + context + 1, len(points))
    frac = np.arange(1, per_interval) / per_interval
    u = (knots[k0:k1, None] + np.diff(knots)[k0:k1, None] * frac[None, :]).ravel()
    x = path.eval_u(u, 0)[0]
    # the distance to the sample's own chord (points i, i+1 of its knot interval i) bounds
    # its distance from the polyline; only samples whose bound comes near the tolerance
    # are measured exactly (most of a smooth fit is far inside it), so `over` and every
    # reported distance are those of measuring all of them
    dev = _own_chord_distance(x, points, path.path_scale, k0, k1, per_interval - 1, lo, hi)
    near = np.flatnonzero(dev > tolerance * (1.0 - _BOUND_REL))
    if near.size:
        dev[near] = PolylineDistance(points[lo:hi], path.path_scale)(x[near])
    return excursion_runs(path, u, dev, tolerance)
