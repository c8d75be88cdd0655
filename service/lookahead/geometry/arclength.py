"""Arc length s(u) and its inverse u(s) for a curve given by its speed sigma(u) = ds/du.

scipy has no arc-length routine for piecewise curves, and `scipy.integrate.quad` is
scalar (one adaptive call per evaluation), so we integrate by hand with 16-node
Gauss-Legendre rules on "leaves": each knot interval is bisected adaptively (only where
needed) until every leaf's rule agrees with the sum over its two halves to 1e-14 of the
interval's length. Where the path nearly reverses, sigma(u) dips to almost 0 over a
tiny stretch of u; the bisection then concentrates its leaves there, and the rest of the
interval stays in a few large leaves.

The arc length at every leaf edge is tabulated (cumulative sum), and s(u) integrates
with one 16-node rule from the edge of u's own leaf only. Each leaf's rule is converged,
so s(u) is accurate and smooth to rounding, not just at the knots (a fixed split of the
whole interval, re-integrated from the knot for every u, left ~1e-7 mm of uneven noise
in x(s) wherever it had not converged). u(s) is solved by safeguarded Newton steps inside
the bracketing leaf (ds/du = sigma is known exactly), 17 speed evaluations per step. The
first guess is the cubic Hermite u(s) from the speeds at the leaf's ends, and a Newton step
is accepted without another quadrature when its Taylor bound (max |dsigma/du| dn^2 / 2,
from a per-leaf estimate of the slope of sigma) is below the rounding of s: on smooth
leaves one quadrature per sample, where the linear guess with checked steps took 2 to 4.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

SpeedFn = Callable[[np.ndarray], np.ndarray]

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)
#: a leaf is converged when halving it changes its length by <= this times its interval's
_REL_TOL = 1e-14
#: bisection depth cap: 2^-50 of a knot interval is at the rounding of u
_MAX_DEPTH = 50
_TINY = np.finfo(float).tiny
_EPS = np.finfo(float).eps
#: steps per leaf of the slope bound of sigma (see `ArcLengthTable.slope_bounds`): 33
#: speed evaluations once per leaf where a step needs it, against a check (17) a sample;
#: 1.0-1.04 quadratures a sample on the tube, hoop, rand6, fourier and near-cusp cycloid
#: corpus paths, 2.7 on n-butterfly (long B-spline leaves), bench/engine_profile paths
_SLOPE_STEPS = 32


def gauss_length(speed: SpeedFn, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Integral of speed over [a_i, b_i] by one 16-node Gauss-Legendre rule (vectorized).

    Row sums go through `np.sum` over a contiguous axis (not BLAS), so a row's result
    does not depend on how many rows are evaluated together (streaming determinism)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    half = 0.5 * (b - a)
    nodes = a[:, None] + half[:, None] * (1.0 + _GL_NODES[None, :])
    vals = speed(nodes.ravel()).reshape(nodes.shape)
    return half * np.sum(vals * _GL_WEIGHTS, axis=1)


@dataclass(frozen=True)
class Leaves:
    """Quadrature leaves tiling consecutive knot intervals, in increasing u.

    start: (nleaf,) left end of each leaf (u); a leaf ends where the next one starts (the
    last one at the last knot). length: (nleaf,) arc length of each leaf (path units).
    count: (nint,) number of leaves in each knot interval."""

    start: np.ndarray
    length: np.ndarray
    count: np.ndarray

    @property
    def first_leaf(self) -> np.ndarray:
        """(nint + 1,) index of each knot interval's first leaf (last entry: nleaf)."""
        return np.concatenate([[0], np.cumsum(self.count)])

    def intervals(self, k0: int, k1: int | None = None) -> Leaves:
        """The leaves of knot intervals k0..k1-1."""
        first = self.first_leaf
        k1 = self.count.size if k1 is None else k1
        lo, hi = first[k0], first[k1]
        return Leaves(self.start[lo:hi], self.length[lo:hi], self.count[k0:k1])

    @staticmethod
    def concat(parts: Sequence[Leaves]) -> Leaves:
        """Leaves of consecutive runs of knot intervals, joined."""
        return Leaves(*(np.concatenate([getattr(p, f) for p in parts])
                        for f in ("start", "length", "count")))


def adaptive_leaves(speed: SpeedFn, knots: np.ndarray) -> Leaves:
    """Bisect each knot interval [knots[i], knots[i+1]] until every leaf is converged.

    A leaf is accepted (with its own one-rule length) when the rule over its two halves
    differs by at most 1e-14 of its interval's length, or by 64 ulp of the leaf's length
    (rounding), or at depth 50. Each interval is refined on its own: its leaves depend
    only on its speed function, not on the other intervals."""
    knots = np.asarray(knots, dtype=float)
    lo, hi = knots[:-1], knots[1:]
    owner = np.arange(lo.size)
    val = gauss_length(speed, lo, hi)
    tol = _REL_TOL * np.abs(val)
    done: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for depth in range(_MAX_DEPTH + 1):
        if not lo.size:
            break
        mid = 0.5 * (lo + hi)
        left, right = gauss_length(speed, lo, mid), gauss_length(speed, mid, hi)
        floor = 64.0 * _EPS * (np.abs(left) + np.abs(right))
        ok = np.abs(left + right - val) <= np.maximum(tol[owner], floor)
        ok |= (mid <= lo) | (mid >= hi) | (depth == _MAX_DEPTH)
        done.append((lo[ok], val[ok], owner[ok]))
        split = ~ok
        lo, hi = np.concatenate([lo[split], mid[split]]), np.concatenate([mid[split], hi[split]])
        val = np.concatenate([left[split], right[split]])
        owner = np.concatenate([owner[split], owner[split]])
    start, length, owners = (np.concatenate(x) for x in zip(*done, strict=True))
    order = np.argsort(start, kind="stable")  # knots strictly increase: leaves are disjoint
    count = np.bincount(owners, minlength=knots.size - 1)
    return Leaves(start[order], length[order], count)


class ArcLengthTable:
    """s(u) and u(s) over knot intervals; `s_knots[i]` is the arc length at `knots[i]`.
    The inversion's per-leaf data are computed lazily, for the leaves it visits.

    `leaves` reuses an earlier `adaptive_leaves(speed, knots)` (e.g. of final pieces of
    a streaming fit); it must tile exactly these knots."""

    def __init__(self, speed: SpeedFn, knots: np.ndarray, leaves: Leaves | None = None) -> None:
        self.speed = speed
        self.knots = np.asarray(knots, dtype=float)
        self.leaves = adaptive_leaves(speed, self.knots) if leaves is None else leaves
        if self.leaves.count.size != self.knots.size - 1:
            raise ValueError("arc length: leaves do not match the knot intervals")
        self.edges = np.concatenate([self.leaves.start, self.knots[-1:]])
        # np.cumsum is sequential: s at a leaf edge does not depend on later leaves
        self.s_edges = np.concatenate([[0.0], np.cumsum(self.leaves.length)])
        self.s_knots = self.s_edges[self.leaves.first_leaf]
        self._edge_speeds: np.ndarray | None = None  # see edge_speeds
        self._slope_bounds: np.ndarray | None = None  # see slope_bounds

    @property
    def length(self) -> float:
        return float(self.s_edges[-1])

    @property
    def lengths(self) -> np.ndarray:
        """(nint,) arc length of each knot interval."""
        return np.diff(self.s_knots)

    def _leaf_of(self, values: np.ndarray, table: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(table, values, side="right") - 1
        return np.clip(idx, 0, self.edges.size - 2)

    def s_of_u(self, u: np.ndarray) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), self.knots[0], self.knots[-1])
        idx = self._leaf_of(u, self.edges)
        return self.s_edges[idx] + gauss_length(self.speed, self.edges[idx], u)

    def edge_speeds(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """sigma at the start and at the end of leaves idx (computed once per edge, on
        first use)."""
        if self._edge_speeds is None:
            self._edge_speeds = np.full(self.edges.size, np.nan)
        table = self._edge_speeds
        need = np.isnan(table[idx]) | np.isnan(table[idx + 1])
        if need.any():
            missing = np.unique(np.concatenate([idx[need], idx[need] + 1]))
            table[missing] = np.asarray(self.speed(self.edges[missing]), dtype=float)
        return table[idx], table[idx + 1]

    def slope_bounds(self, idx: np.ndarray) -> np.ndarray:
        """An estimate of max |d sigma/du| over each of leaves idx (path units / u^2):
        twice the largest difference quotient of sigma over 32 equal steps of the leaf. A
        converged leaf's sigma is smooth at that resolution (its 16-node rule is exact to
        1e-14), so the factor 2 is a margin. Computed once per leaf, on first use (33
        speed evaluations)."""
        if self._slope_bounds is None:
            self._slope_bounds = np.full(self.leaves.start.size, np.nan)
        table = self._slope_bounds
        need = np.isnan(table[idx])
        if need.any():
            missing = np.unique(idx[need])
            lo, width = self.edges[missing], self.edges[missing + 1] - self.edges[missing]
            grid = lo[:, None] + width[:, None] * np.linspace(0.0, 1.0, _SLOPE_STEPS + 1)
            grid[:, -1] = self.edges[missing + 1]
            sig = np.asarray(self.speed(grid.ravel()), dtype=float).reshape(grid.shape)
            quot = np.max(np.abs(np.diff(sig, axis=1)), axis=1) * _SLOPE_STEPS
            table[missing] = 2.0 * quot / np.maximum(width, _TINY)
        return table[idx]

    def u_of_s(self, s: np.ndarray) -> np.ndarray:
        """u at arc lengths s (clipped to [0, length]): s(u) = s to the rounding of s."""
        return self.invert(s)[0]

    def invert(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """u(s) and the number of quadratures (residual evaluations) each sample took."""
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.length)
        idx = self._leaf_of(s, self.s_edges)
        lo, hi = self.edges[idx], self.edges[idx + 1]
        s_lo, span = self.s_edges[idx], self.s_edges[idx + 1] - self.s_edges[idx]
        u = lo + (hi - lo) * _hermite_fraction(s - s_lo, span, hi - lo, *self.edge_speeds(idx))
        # converged when the residual is at the rounding of s itself
        floor = 4.0 * _EPS * (np.abs(s) + span)
        out = np.empty_like(u)
        count = np.zeros(s.size, dtype=np.int64)
        # Newton on F(u) = s(u) - s; each iterate is kept inside its bracket [a, b],
        # which is shrunk from the sign of F, so a bad step (sigma ~ 0) cannot escape.
        # The working arrays hold the unconverged samples only (compacted when some
        # converge, not gathered by index every step).
        a, b, pos, leaf = lo, hi, np.arange(s.size), idx
        for it in range(1, 61):
            err = s_lo + gauss_length(self.speed, lo, u) - s
            above = err > 0
            b = np.where(above, u, b)
            a = np.where(above, a, u)
            un = u - err / np.maximum(self.speed(u), _TINY)
            outside = (un <= a) | (un >= b)
            un_safe = np.where(outside, 0.5 * (a + b), un)
            collapsed = b - a <= 4.0 * _EPS * np.maximum(np.abs(a), np.abs(b))
            done = ((np.abs(err) <= floor) | (np.abs(un_safe - u) <= 2.0 * _EPS * np.abs(u))
                    | collapsed)
            res = np.where(done, u, un_safe)
            # Taylor: the residual at a Newton step dn is sigma'(xi) dn^2 / 2 exactly, so
            # a step whose bound is below a quarter of the rounding floor needs no check
            cand = ~done & ~outside
            if cand.any():
                dn2 = (un[cand] - u[cand]) ** 2
                ok = 0.5 * self.slope_bounds(leaf[cand]) * dn2 <= 0.25 * floor[cand]
                done[np.flatnonzero(cand)[ok]] = True
            un = un_safe
            if it == 60 or done.all():
                out[pos] = res
                count[pos] = it
                break
            if done.any():
                out[pos[done]] = res[done]
                count[pos[done]] = it
                keep = ~done
                pos, leaf, lo, s_lo, s, floor, a, b = (
                    x[keep] for x in (pos, leaf, lo, s_lo, s, floor, a, b))
                un = un[keep]
            u = un
        return out, count


def _hermite_fraction(ds: np.ndarray, span: np.ndarray, width: np.ndarray,
                      sig_lo: np.ndarray, sig_hi: np.ndarray) -> np.ndarray:
    """(u - leaf start) / leaf width at arc length ds into each leaf: the cubic Hermite
    u(s) through both leaf ends with slopes du/ds = 1/sigma there (the initial guess of
    the inversion). Slopes are capped at 3 times the leaf's mean du/ds (the Fritsch-
    Carlson bound: the cubic stays monotone), so sigma ~ 0 at an edge (cusp) is harmless.
    Hand-written: scipy's CubicHermiteSpline builds one spline over all its x, while this
    evaluates a different cubic per sample (its own leaf) in a few vector operations."""
    t = np.clip(ds / np.maximum(span, _TINY), 0.0, 1.0)
    mean = span / np.maximum(width, _TINY)  # mean sigma over the leaf
    m0 = np.minimum(mean / np.maximum(sig_lo, _TINY), 3.0)
    m1 = np.minimum(mean / np.maximum(sig_hi, _TINY), 3.0)
    t2 = t * t
    r = t2 - t  # t^2 - t
    # h01 + m0 h10 + m1 h11 with h01 = 3t^2 - 2t^3, h10 = t (t - 1)^2, h11 = t^2 (t - 1)
    return np.clip(t2 * (3.0 - 2.0 * t) + (m0 * (t - 1.0) + m1 * t) * r, 0.0, 1.0)
