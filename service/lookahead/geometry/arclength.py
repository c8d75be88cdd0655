"""Arc length s(u) and its inverse u(s) for a curve given by its speed sigma(u) = ds/du.

scipy has no arc-length routine for piecewise curves, and `scipy.integrate.quad` is
scalar (one adaptive call per evaluation), so we integrate by hand: Gauss-Legendre
quadrature (16 nodes) per knot interval, with each interval split into 2^k equal parts
until doubling the split changes its length by < 1e-13 relative. u(s) is solved by
safeguarded Newton steps inside the bracketing interval (ds/du = sigma is known exactly).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

SpeedFn = Callable[[np.ndarray], np.ndarray]

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)
_REL_TOL = 1e-13
_MAX_SPLIT = 256
_TINY = np.finfo(float).tiny
_EPS = np.finfo(float).eps


def gauss_length(speed: SpeedFn, a: np.ndarray, b: np.ndarray, split: np.ndarray) -> np.ndarray:
    """Integral of speed over [a_i, b_i], each split into split_i equal parts (vectorized)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    split = np.broadcast_to(np.asarray(split, dtype=int), a.shape)
    out = np.zeros(a.shape)
    for m in np.unique(split):
        sel = split == m
        lo, hi = a[sel], b[sel]
        h = (hi - lo) / m
        starts = lo[:, None] + h[:, None] * np.arange(m)[None, :]  # (k, m)
        half = 0.5 * h[:, None, None]
        nodes = starts[:, :, None] + half * (1.0 + _GL_NODES[None, None, :])
        vals = speed(nodes.ravel()).reshape(nodes.shape)
        out[sel] = np.sum(half[:, :, 0] * (vals @ _GL_WEIGHTS), axis=1)
    return out


def interval_lengths(speed: SpeedFn, knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lengths of the knot intervals and the split each needed to converge.

    Returns (lengths, split), both of shape (len(knots) - 1,).
    """
    a, b = knots[:-1], knots[1:]
    split = np.ones(a.shape, dtype=int)
    lengths = gauss_length(speed, a, b, split)
    todo = np.arange(a.size)
    while todo.size:
        finer = gauss_length(speed, a[todo], b[todo], 2 * split[todo])
        scale = np.maximum(np.abs(finer), _TINY)
        converged = np.abs(finer - lengths[todo]) <= _REL_TOL * scale
        lengths[todo] = finer
        split[todo] *= 2
        todo = todo[~converged & (split[todo] < _MAX_SPLIT)]
    return lengths, split


class ArcLengthTable:
    """s(u) and u(s) over knot intervals; `s_knots[i]` is the arc length at `knots[i]`."""

    def __init__(
        self,
        speed: SpeedFn,
        knots: np.ndarray,
        lengths: np.ndarray | None = None,
        split: np.ndarray | None = None,
    ) -> None:
        self.speed = speed
        self.knots = np.asarray(knots, dtype=float)
        if lengths is None or split is None:
            lengths, split = interval_lengths(speed, self.knots)
        self.lengths = np.asarray(lengths, dtype=float)
        self.split = np.asarray(split, dtype=int)
        self.s_knots = np.concatenate([[0.0], np.cumsum(self.lengths)])

    @property
    def length(self) -> float:
        return float(self.s_knots[-1])

    def interval_of_u(self, u: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(self.knots, u, side="right") - 1
        return np.clip(idx, 0, len(self.knots) - 2)

    def s_of_u(self, u: np.ndarray) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), self.knots[0], self.knots[-1])
        idx = self.interval_of_u(u)
        return self.s_knots[idx] + gauss_length(self.speed, self.knots[idx], u, self.split[idx])

    def u_of_s(self, s: np.ndarray) -> np.ndarray:
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.length)
        idx = np.searchsorted(self.s_knots, s, side="right") - 1
        idx = np.clip(idx, 0, len(self.knots) - 2)
        lo, hi = self.knots[idx], self.knots[idx + 1]
        s_lo, s_hi = self.s_knots[idx], self.s_knots[idx + 1]
        frac = (s - s_lo) / np.maximum(s_hi - s_lo, _TINY)
        u = lo + (hi - lo) * frac
        # Newton on F(u) = s(u) - s; each iterate is kept inside its bracket [lo, hi],
        # which is shrunk from the sign of F, so a bad step cannot escape the interval.
        a, b = lo.copy(), hi.copy()
        active = np.arange(s.size)
        for _ in range(60):
            if not active.size:
                break
            ua = u[active]
            err = s_lo[active] + gauss_length(
                self.speed, lo[active], ua, self.split[idx[active]]
            ) - s[active]
            above = err > 0
            b[active] = np.where(above, ua, b[active])
            a[active] = np.where(above, a[active], ua)
            step = err / np.maximum(self.speed(ua), _TINY)
            un = ua - step
            outside = (un <= a[active]) | (un >= b[active])
            un = np.where(outside, 0.5 * (a[active] + b[active]), un)
            # converged when the residual is at the roundoff of s itself
            floor = 1e-13 * (s_hi[active] - s_lo[active]) + 8 * _EPS * np.abs(s[active])
            done = (np.abs(err) <= floor) | (np.abs(un - ua) <= 1e-15 * (hi - lo)[active])
            u[active] = np.where(done, ua, un)
            active = active[~done]
        return u
