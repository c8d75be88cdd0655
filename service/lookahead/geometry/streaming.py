"""Incremental fit of a point stream that arrives in chunks (PROTOCOL.md kind = points).

The parameter u is the cumulative chord length in the path metric (as `fit_points`).
Repeated points and zero-length moves (step <= `min_step` path units from the last kept
point) are skipped and counted in `skipped`.

`cubic`: a C2 cubic B-spline with a knot at every kept point (natural end conditions,
x'' = 0 at both ends of the whole stream). Any control points give an exactly C2 curve;
only the interpolation conditions couple them globally, and the influence of a data point
decays by ~0.27 per knot. So control points are solved in fixed blocks of `BLOCK` (32)
along the stream, each from a window of the data reaching `LOOKAHEAD` (40) points beyond
the block on both sides (scipy `make_interp_spline`). A block is final once the point
`LOOKAHEAD` past its end has arrived; windows sit at fixed stream indices, so the final
geometry does not depend on how the stream was chunked. The truncation changes the
interpolation residual by ~0.27^40 (below roundoff), never the C2 continuity.
Tail (not yet final): at most BLOCK + LOOKAHEAD + 2 = 74 knot intervals behind the newest
point. Cost of `extend`: O(chunk + BLOCK + LOOKAHEAD).

`pchip`: the scipy shape-preserving slopes are local (knot i uses points i-1..i+1), so
every piece except the newest one is final. Tail: 1 knot interval.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline, PchipInterpolator, PPoly, make_interp_spline

from lookahead.geometry.arclength import Leaves
from lookahead.geometry.base import Path
from lookahead.geometry.piecewise import ppoly_from_bspline
from lookahead.geometry.spline_path import FIT_METHODS, SplinePath, validate_points

BLOCK = 32
LOOKAHEAD = 40
#: steps at or below this length (path units) are zero-length moves
MIN_STEP = 1e-9


class _Buffer:
    """A growing array along axis `axis` with amortized O(1) appends."""

    def __init__(self, shape_rest: tuple[int, ...], axis: int = 0, dtype: type = float) -> None:
        self._axis = axis
        shape = list(shape_rest)
        shape.insert(axis, 64)
        self._data = np.empty(shape, dtype=dtype)
        self.size = 0

    def append(self, values: np.ndarray) -> None:
        values = np.asarray(values)
        n = values.shape[self._axis]
        cap = self._data.shape[self._axis]
        if self.size + n > cap:
            new_cap = max(2 * cap, self.size + n)
            pad = list(self._data.shape)
            pad[self._axis] = new_cap - cap
            self._data = np.concatenate([self._data, np.empty(pad, self._data.dtype)], self._axis)
        index = [slice(None)] * self._data.ndim
        index[self._axis] = slice(self.size, self.size + n)
        self._data[tuple(index)] = values
        self.size += n

    def view(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        index = [slice(None)] * self._data.ndim
        index[self._axis] = slice(start, self.size if stop is None else min(stop, self.size))
        return self._data[tuple(index)]


class PointStream:
    """The input side of a streaming fit: a point stream (axis units) received in chunks,
    repeats skipped, parameterized by cumulative chord length u (bit-identical whatever
    the chunking). Subclasses build the geometry in `_finalize` (called after each chunk)."""

    def __init__(self, naxes: int, path_scale: np.ndarray, min_step: float = MIN_STEP) -> None:
        self.naxes = int(naxes)
        self.path_scale = np.asarray(path_scale, dtype=float).reshape(-1)
        if self.path_scale.size != self.naxes:
            raise ValueError(f"path_scale: expected {self.naxes} entries")
        self.min_step = float(min_step)
        self.skipped = 0
        self.received = 0
        self._finished = False
        self._u = _Buffer(())
        self._pts = _Buffer((self.naxes,))
        self._path: Path | None = None

    # --- input ------------------------------------------------------------------------
    @property
    def npoints(self) -> int:
        """Number of kept (distinct) points."""
        return self._u.size

    def extend(self, points: np.ndarray) -> None:
        """Append a chunk (n, naxes) of points; the chunk does not repeat the last point."""
        if self._take(points) is not None:
            self._finalize()

    def points(self) -> np.ndarray:
        """The kept points (npoints, naxes), axis units (a read-only view)."""
        view = self._pts.view()
        view.flags.writeable = False
        return view

    def _take(self, points: np.ndarray) -> np.ndarray | None:
        """Validate and append a chunk (the geometry is not updated: `_finalize`); the
        indices of its kept rows (None if none)."""
        if self._finished:
            raise ValueError("points: the stream is finished")
        arr = validate_points(points, self.naxes, what=f"points (stream from {self.received})")
        self.received += len(arr)
        kept, steps, rows = self._drop_repeats(arr)
        if kept.size == 0:
            return None
        # np.cumsum is sequential: u is bit-identical whatever the chunking
        if self._u.size:
            u_new = np.cumsum(np.concatenate([[self._u.view()[-1]], steps]))[1:]
        else:  # the stream's first point is at u = 0 (its step is inf)
            u_new = np.cumsum(np.concatenate([[0.0], steps[1:]]))
        self._u.append(u_new)
        self._pts.append(kept)
        self._path = None
        return rows

    def _finalize(self) -> None:
        raise NotImplementedError

    def _drop_repeats(self, arr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Kept rows of `arr`, their metric steps from the previous kept point and their
        row indices in `arr`."""
        prev = self._pts.view()[-1] if self._pts.size else None
        chain = arr if prev is None else np.vstack([prev, arr])
        steps = self._metric_steps(np.diff(chain, axis=0))
        if prev is None:
            steps = np.concatenate([[np.inf], steps])
        if np.all(steps > self.min_step):
            return arr, steps, np.arange(len(arr))
        # rare path: a sequential pass so a run of tiny moves is measured from the last
        # kept point, not from its (skipped) predecessor
        keep_rows, keep_steps, keep_idx = [], [], []
        last = prev
        for i, row in enumerate(arr):
            step = np.inf if last is None else float(self._metric_steps(row - last))
            if step <= self.min_step:
                self.skipped += 1
                continue
            keep_rows.append(row)
            keep_steps.append(step)
            keep_idx.append(i)
            last = row
        if not keep_rows:
            return np.empty((0, self.naxes)), np.empty(0), np.empty(0, dtype=int)
        return np.array(keep_rows), np.array(keep_steps), np.array(keep_idx)

    def _metric_steps(self, deltas: np.ndarray) -> np.ndarray:
        """Metric lengths of point differences (last axis: the axes). One formula for both
        passes of `_drop_repeats`: np.linalg.norm rounds differently, and a skipped repeat
        must leave the same u as a stream without it."""
        return np.sqrt(np.sum((deltas * self.path_scale) ** 2, axis=-1))

    @property
    def finished(self) -> bool:
        return self._finished


class StreamingFit(PointStream):
    """Fit of a point stream (axis units) received in chunks; see the module docstring."""

    def __init__(
        self,
        naxes: int,
        path_scale: np.ndarray,
        method: str = "cubic",
        min_step: float = MIN_STEP,
    ) -> None:
        if method not in FIT_METHODS:
            raise ValueError(f"fit: unknown method {method!r}, expected one of {FIT_METHODS}")
        super().__init__(naxes, path_scale, min_step)
        self.method = method
        self._ctrl = _Buffer((self.naxes,))  # final B-spline control points (cubic)
        self._coef = _Buffer((4, self.naxes), axis=1)  # final pieces, PPoly layout
        # arc-length quadrature leaves of the final pieces (`arclength.Leaves`)
        self._leaf_start = _Buffer(())
        self._leaf_length = _Buffer(())
        self._leaf_count = _Buffer((), dtype=int)
        self._s_final = 0.0
        self._final: tuple[int, Path] | None = None  # (final intervals, `final_path()`)

    # --- finalization -----------------------------------------------------------------
    def _knots(self, lo: int, hi: int) -> np.ndarray:
        """Global cubic B-spline knots t[lo:hi] (t_i = u_{i-3}, clamped at both ends)."""
        n = self._u.size - 1
        return self._u.view()[np.clip(np.arange(lo, hi) - 3, 0, n)]

    def _solve_window(self, a: int, e: int) -> np.ndarray:
        """Control points of the natural cubic interpolant of points a..e (window)."""
        u = self._u.view(a, e + 1)
        t = np.concatenate([[u[0]] * 3, u, [u[-1]] * 3])
        return make_interp_spline(u, self._pts.view(a, e + 1), k=3, t=t, bc_type="natural").c

    def _finalize(self) -> None:
        n = self._u.size - 1
        if self.method == "pchip":
            self._append_final_pieces(max(n - 1, 0))
            return
        nb = self._ctrl.size // BLOCK
        while (nb + 1) * BLOCK + LOOKAHEAD <= n:
            a = max(0, nb * BLOCK - LOOKAHEAD)
            ctrl = self._solve_window(a, (nb + 1) * BLOCK + LOOKAHEAD)
            self._ctrl.append(ctrl[nb * BLOCK - a : (nb + 1) * BLOCK - a])
            nb += 1
        self._append_final_pieces(max(self._ctrl.size - 3, 0))

    def _pieces(self, k0: int, k1: int, tail_ctrl: np.ndarray | None = None) -> PPoly:
        """PPoly of knot intervals k0..k1-1 from control points (final, then `tail_ctrl`)."""
        if self.method == "pchip":
            a = max(k0 - 1, 0)
            pch = PchipInterpolator(self._u.view(a, k1 + 2), self._pts.view(a, k1 + 2), axis=0)
            return PPoly(pch.c[:, k0 - a : k1 - a], self._u.view(k0, k1 + 1))
        ctrl = self._ctrl.view(k0)
        if tail_ctrl is not None:
            ctrl = np.concatenate([ctrl, tail_ctrl])
        spline = BSpline(self._knots(k0, k1 + 7), ctrl[: k1 - k0 + 3], 3)
        return ppoly_from_bspline(spline)

    def _append_final_pieces(self, k1: int) -> None:
        k0 = self._leaf_count.size
        if k1 <= k0:
            return
        pp = self._pieces(k0, k1)
        self._coef.append(pp.c)
        self._append_final_leaves(SplinePath(pp, self.path_scale).leaves)

    def _append_final_leaves(self, leaves: Leaves) -> None:
        self._leaf_start.append(leaves.start)
        self._leaf_length.append(leaves.length)
        self._leaf_count.append(leaves.count)
        # continues the path's own sequential cumsum: bit-identical to its s at the knot
        self._s_final = float(np.cumsum(np.concatenate([[self._s_final], leaves.length]))[-1])

    def _final_leaves(self) -> Leaves:
        return Leaves(self._leaf_start.view(), self._leaf_length.view(), self._leaf_count.view())

    # --- output -----------------------------------------------------------------------
    @property
    def final_length(self) -> float:
        """Arc length (path units) up to which the geometry never changes again."""
        return self._s_final

    def path(self) -> Path:
        """The best current geometry over all kept points (>= 2 needed); identical to the
        final geometry on [0, final_length]."""
        if self._path is not None:
            return self._path
        n = self._u.size - 1
        if n < 1:
            raise ValueError("points: need at least 2 distinct points for a path")
        k0 = self._leaf_count.size
        coef, leaves = self._coef.view(), self._final_leaves()
        if k0 < n:
            tail = self._tail_pieces(k0, n)
            coef = np.concatenate([coef, tail.c], axis=1)
            leaves = Leaves.concat([leaves, SplinePath(tail, self.path_scale).leaves])
        pp = PPoly(coef, self._u.view(), extrapolate=True)
        continuity = 2 if self.method == "cubic" else 1
        self._path = SplinePath(pp, self.path_scale, continuity, leaves=leaves)
        return self._path

    def final_path(self) -> Path | None:
        """The final geometry alone, over its knot intervals (None before there is one):
        the pieces, knots and arc-length leaves of `path()` on [0, final_length], without
        building the tail that later points still change (`path()` solves and integrates
        it on every call after new points)."""
        k0 = self._leaf_count.size
        if k0 < 1:
            return None
        if self._final is None or self._final[0] != k0:
            pp = PPoly(self._coef.view(), self._u.view(0, k0 + 1), extrapolate=True)
            continuity = 2 if self.method == "cubic" else 1
            self._final = (k0, SplinePath(pp, self.path_scale, continuity,
                                          leaves=self._final_leaves()))
        return self._final[1]

    def _tail_pieces(self, k0: int, n: int) -> PPoly:
        """Pieces k0..n-1 from the current data, with the stream's end as the true end."""
        if self.method == "pchip":
            return self._pieces(k0, n)
        f = self._ctrl.size
        a = max(0, f - LOOKAHEAD)
        ctrl = self._solve_window(a, n)
        return self._pieces(k0, n, tail_ctrl=ctrl[f - a :])

    def finish(self) -> Path:
        """End of stream: everything becomes final. Returns the complete path."""
        path = self.path()
        if not self._finished:
            n = self._u.size - 1
            k0 = self._leaf_count.size
            if k0 < n:
                self._coef.append(path.pp.c[:, k0:])
                self._append_final_leaves(path.leaves.intervals(k0))
                self._s_final = path.length
            self._finished = True
        return path
