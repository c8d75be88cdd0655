"""Rows of the feed LP (Fan et al.) on a grid in arc length s.

Variables are q_i = (ds/dt)^2 at nodes s_0 < s_1 < ... < s_N (path units^2 / s^2).
With derivatives of q taken in s (q' = dq/ds, q'' = d2q/ds2) and x', x'', x''' the
path derivatives with respect to s (DESIGN.md "Mathematics"), for every axis k:

    velocity      x'_k sqrt(q)                                  (a bound on q_i)
    acceleration  x''_k q + x'_k q' / 2                          (linear in q)
    jerk          sqrt(q) (x'''_k q + 3/2 x''_k q' + 1/2 x'_k q'') = sqrt(q) L_k(q)

q' and q'' at node i are three-point finite differences over (i-1, i, i+1), valid on a
non-uniform grid. The jerk bound |sqrt(q) L| <= J is linearized at q* by the tangent of
the convex J / sqrt(q):  +-sqrt(q*) L(q) + J q / (2 q*) <= 3/2 J, which is conservative.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from lookahead.geometry.base import Path, arc_length_derivatives


def s_derivatives(d: np.ndarray, path_scale: np.ndarray) -> tuple[np.ndarray, ...]:
    """x_s, x_ss, x_sss (each (n, naxes)) and sigma = ds/du (n,) from d = path.eval_u(u, 3)."""
    sigma, d1, d2, d3 = arc_length_derivatives(d, path_scale)
    return d1, d2, d3, sigma


def midpoint_u(s: np.ndarray, u: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """u at the interval midpoints (s_i + s_i+1) / 2: the cubic Hermite interpolant of the
    nodes' (u, du/ds = 1/sigma), as `sampled_check.analytic_ratios` locates u between
    nodes (the derivatives there within ~0.3 % on 1-3 mm intervals at the issue-13
    Fourier path's near-cusp; an arc-length inversion costs far more). Not where ds/du
    changes fast within the interval: `GridGeometry.sample` inverts exactly there
    (`rough_intervals`)."""
    h = np.diff(s)
    du = 1.0 / sigma
    return 0.5 * (u[:-1] + u[1:]) + 0.125 * h * (du[:-1] - du[1:])


#: an interval over which ds/du (sigma) at its nodes and its Hermite midpoint differs by
#: more than this factor is "rough": the cubic Hermite u(s) of `midpoint_u` and
#: `sampled_check.analytic_ratios` does not hold there, so its midpoint and the check's
#: samples in it get the exact arc-length inversion. Where the smooth G-code fit of the
#: 100k-line winding program leaves a corner blend for a long straight piece, sigma falls
#: from 1.0 to 0.0034 within the blend's last 0.05 mm: the Hermite put u 0.94 (s ~0.9 mm)
#: off in a 0.11 mm interval, the check read x_sss of the blend's middle (9 against 0.3
#: per mm^2 on X) and every repair of the whole-job LP failed there (jerk 4-9x; with the
#: marks it plans, 3000.4 s, 0 violations; c-corners-bspline-2d 1.35 % faster). Trades
#: exact inversions (~30x an evaluation of x(u)) for the Hermite's error: measured on the
#: fast corpus's whole-job grids, the midpoint's error in s left on unmarked intervals is
#: at most 4.9 % of the interval at 1.5 (c-corners-bspline-2d; n-butterfly 1.3 %), 0.26 %
#: at 1.25 (0-15 intervals marked per path, all on c-corners, c-cycloid, n-butterfly),
#: 0.07 % at 1.1 (64); elsewhere sigma changes by < 5 % per interval.
ROUGH_SIGMA_RATIO = 1.25


def rough_intervals(sigma: np.ndarray, sigma_mid: np.ndarray) -> np.ndarray:
    """(N,) True where sigma (ds/du) at the interval's two nodes (`sigma`, (N+1,)) and at
    its midpoint (`sigma_mid`, (N,)) spans more than ROUGH_SIGMA_RATIO: a u(s) that a
    cubic Hermite of the nodes' (u, 1/sigma) does not follow (`ROUGH_SIGMA_RATIO`)."""
    both = np.stack([sigma[:-1], sigma[1:], sigma_mid])
    lo, hi = np.min(both, axis=0), np.max(both, axis=0)
    return ~(hi <= ROUGH_SIGMA_RATIO * lo)  # NaN or sigma 0: rough


@dataclass(frozen=True)
class GridGeometry:
    """Path derivatives w.r.t. s at the grid nodes: d1, d2, d3 have shape (N+1, naxes);
    u is the native parameter and sigma = ds/du at the nodes (for a cheap u(s) between
    them, `sampled_check.analytic_ratios`). mid: (x_s, x_ss, x_sss) at the N interval
    midpoints, each (N, naxes) (rows of NaN where unknown: a seam's joining interval),
    for the midpoint jerk rows (`midpoint_jerk_rows`); None: no such rows. rough: (N,)
    True on intervals where that cheap u(s) does not hold (`rough_intervals`; a seam's
    joining interval on its nodes' sigma alone): u there comes from the exact arc-length
    inversion; None: not known (the cheap u(s) everywhere)."""

    s: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    d3: np.ndarray
    u: np.ndarray | None = None
    sigma: np.ndarray | None = None
    mid: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    rough: np.ndarray | None = None

    @classmethod
    def sample(cls, path: Path, s: np.ndarray, midpoints: bool = True) -> GridGeometry:
        """The geometry at the nodes s (path units, increasing); with `midpoints`, also at
        the interval midpoints (u by `midpoint_u`, exact on rough intervals)."""
        s = np.asarray(s, dtype=float)
        u = path.u_of_s(s)
        d1, d2, d3, sigma = s_derivatives(path.eval_u(u, order=3), path.path_scale)
        if s.size < 2:
            return cls(s, d1, d2, d3, u, sigma, None, np.zeros(0, dtype=bool))
        u_mid = midpoint_u(s, u, sigma)
        d_mid = path.eval_u(u_mid, order=3 if midpoints else 1)
        scale = np.asarray(path.path_scale, dtype=float)
        rough = rough_intervals(sigma, np.linalg.norm(d_mid[1] * scale, axis=1))
        mid = None
        if midpoints:
            if np.any(rough):
                u_mid[rough] = path.u_of_s(0.5 * (s[:-1] + s[1:])[rough])
                d_mid[:, rough] = path.eval_u(u_mid[rough], order=3)
            mid = s_derivatives(d_mid, path.path_scale)[:3]
        return cls(s, d1, d2, d3, u, sigma, mid, rough)

    @property
    def n_nodes(self) -> int:
        return int(self.s.size)

    def take(self, nodes: slice) -> GridGeometry:
        """The geometry of a run of nodes (a replan reuses its previous grid's)."""
        mid = rough = None
        start, stop, step = nodes.indices(self.n_nodes)
        if step == 1:
            if self.mid is not None:
                mid = tuple(m[start:max(stop - 1, start)] for m in self.mid)
            if self.rough is not None:
                rough = self.rough[start:max(stop - 1, start)]
        return GridGeometry(self.s[nodes], self.d1[nodes], self.d2[nodes], self.d3[nodes],
                            None if self.u is None else self.u[nodes],
                            None if self.sigma is None else self.sigma[nodes], mid, rough)

    @staticmethod
    def join(head: GridGeometry, tail: GridGeometry) -> GridGeometry:
        """Nodes of `head` then those of `tail` (tail.s[0] > head.s[-1])."""
        def cat(a, b):
            return None if a is None or b is None else np.concatenate([a, b])

        mid = None
        if head.mid is not None and tail.mid is not None:
            gap = np.full((1, head.d1.shape[1]), np.nan)  # the joining interval: unknown
            mid = tuple(np.concatenate([a, gap, b]) for a, b in zip(head.mid, tail.mid,
                                                                       strict=True))
        rough = None  # the joining interval: judged on its two nodes' sigma alone
        if (head.rough is not None and tail.rough is not None and head.sigma is not None
                and tail.sigma is not None):
            ends = np.array([head.sigma[-1], tail.sigma[0]])
            gap = rough_intervals(ends, ends[:1])
            rough = np.concatenate([head.rough, gap, tail.rough])
        return GridGeometry(np.concatenate([head.s, tail.s]), cat(head.d1, tail.d1),
                            cat(head.d2, tail.d2), cat(head.d3, tail.d3), cat(head.u, tail.u),
                            cat(head.sigma, tail.sigma), mid, rough)


@dataclass
class Tightening:
    """Per-node factors (<= 1) on the velocity, acceleration and jerk limits."""

    vel: np.ndarray
    acc: np.ndarray
    jerk: np.ndarray

    @classmethod
    def uniform(cls, n: int, vel: float, acc: float, jerk: float) -> Tightening:
        return cls(np.full(n, vel), np.full(n, acc), np.full(n, jerk))


@dataclass(frozen=True)
class Rows:
    """Linear rows lower <= A q <= upper in the unscaled variables q (A is CSR)."""

    A: sp.csr_matrix
    lower: np.ndarray
    upper: np.ndarray

    @staticmethod
    def stack(parts: list[Rows], n: int) -> Rows:
        """All rows in one CSR matrix, assembled from the parts' arrays (sp.vstack costs
        ~0.5 ms per call in scipy's checks, which the LP pays every pass)."""
        parts = [p for p in parts if p.A.shape[0] > 0]
        if not parts:
            return Rows(sp.csr_matrix((0, n)), np.empty(0), np.empty(0))
        offsets = np.cumsum([0] + [p.A.nnz for p in parts])
        indptr = np.concatenate([[0]] + [p.A.indptr[1:] + o for p, o in
                                         zip(parts, offsets[:-1], strict=True)])
        A = sp.csr_matrix((np.concatenate([p.A.data for p in parts]),
                           np.concatenate([p.A.indices for p in parts]), indptr),
                          shape=(int(indptr.size - 1), n))
        return Rows(A, np.concatenate([p.lower for p in parts]),
                    np.concatenate([p.upper for p in parts]))


def free_rows(rows: Rows, fixed: np.ndarray) -> Rows:
    """The rows with a nonzero coefficient on at least one variable not in `fixed` (a
    boolean mask): rows on fixed variables only are constants that the solver can only
    report infeasible, to its tolerance (a seam's head was verified with its plan)."""
    A = rows.A.tocsr()
    pattern = sp.csr_matrix(((np.abs(A.data) > 0).astype(float), A.indices, A.indptr),
                            shape=A.shape)
    keep = (pattern @ (~fixed).astype(float)) > 0
    if np.all(keep):
        return rows
    return Rows(A[keep], rows.lower[keep], rows.upper[keep])


def banded(coef: np.ndarray, first_col: np.ndarray, n: int) -> sp.csr_matrix:
    """CSR matrix whose row r holds coef[r, :] on columns first_col[r] .. + width - 1."""
    m, width = coef.shape
    indices = (first_col[:, None] + np.arange(width)[None, :]).ravel()
    indptr = np.arange(m + 1) * width
    return sp.csr_matrix((coef.ravel(), indices, indptr), shape=(m, n))


def fd_weights(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Three-point weights on (i-1, i, i+1) for q' and q'' at the interior nodes.

    Returns (w1, w2), each of shape (N-1, 3). Exact for quadratics on any spacing.
    """
    h1 = np.diff(s)[:-1]
    h2 = np.diff(s)[1:]
    hs = h1 + h2
    w1 = np.stack([-h2 / (h1 * hs), (h2 - h1) / (h1 * h2), h1 / (h2 * hs)], axis=1)
    w2 = np.stack([2.0 / (h1 * hs), -2.0 / (h1 * h2), 2.0 / (h2 * hs)], axis=1)
    return w1, w2


def backward_slope_weights(s: np.ndarray) -> np.ndarray:
    """Three-point weights on (N-2, N-1, N) for q' at the last node (exact for quadratics)."""
    h1, h2 = s[-2] - s[-3], s[-1] - s[-2]
    hs = h1 + h2
    return np.array([h2 / (h1 * hs), -hs / (h1 * h2), (hs + h2) / (h2 * hs)])


def forward_slope_weights(s: np.ndarray) -> np.ndarray:
    """Three-point weights on (0, 1, 2) for q' at the first node (exact for quadratics)."""
    h1, h2 = s[1] - s[0], s[2] - s[1]
    hs = h1 + h2
    return np.array([-(h1 + hs) / (h1 * hs), hs / (h1 * h2), -h1 / (h2 * hs)])


def velocity_caps(geo: GridGeometry, vmax: np.ndarray) -> np.ndarray:
    """Upper bound on q_i from the axis velocity limits: min_k (vmax_k / |x'_k|)^2."""
    with np.errstate(divide="ignore"):
        per_axis = (vmax[None, :] / np.abs(geo.d1)) ** 2
    return np.min(per_axis, axis=1)


def _tridiagonal(coef: np.ndarray, rows_of: np.ndarray, n: int) -> sp.csr_matrix:
    """Sparse matrix whose row r has coef[r, 0..2] on columns rows_of[r] - 1 .. + 1."""
    return banded(coef, rows_of - 1, n)


def acceleration_rows(geo: GridGeometry, amax: np.ndarray, scale: np.ndarray) -> Rows:
    """|x''_k q_i + x'_k q'_i / 2| <= scale_i amax_k at the interior nodes, every axis."""
    n = geo.n_nodes
    w1, _ = fd_weights(geo.s)
    nodes = np.arange(1, n - 1)
    parts = []
    for k in range(geo.d1.shape[1]):
        coef = 0.5 * geo.d1[nodes, k, None] * w1
        coef[:, 1] += geo.d2[nodes, k]
        bound = amax[k] * scale[nodes]
        parts.append(Rows(_tridiagonal(coef, nodes, n), -bound, bound))
    return Rows.stack(parts, n)


def end_acceleration_rows(geo: GridGeometry, amax: np.ndarray, scale: float) -> Rows:
    """Axis acceleration at the last node (used when the plan ends moving), backward slope."""
    n = geo.n_nodes
    w = backward_slope_weights(geo.s)
    A = np.zeros((geo.d1.shape[1], n))
    A[:, -3:] = 0.5 * geo.d1[-1, :, None] * w[None, :]
    A[:, -1] += geo.d2[-1]
    bound = amax * scale
    return Rows(sp.csr_matrix(A), -bound, bound)


def start_slope_row(geo: GridGeometry, a0: float) -> Rows:
    """q'(s_0) / 2 = a0: the plan starts with path acceleration a0 (forward slope)."""
    n = geo.n_nodes
    A = np.zeros((1, n))
    A[0, :3] = 0.5 * forward_slope_weights(geo.s)
    return Rows(sp.csr_matrix(A), np.array([a0]), np.array([a0]))


def start_jerk_rows(geo: GridGeometry, jmax: np.ndarray, scale: float, v0: float,
                    a0: float) -> Rows:
    """The axis jerk at the first node of a moving start, x''' v0^3 + 3 x'' v0 a0 + x' j0,
    within +-scale jmax, with the path jerk j0 = v0 q''/2 and q'' of the quadratic
    through nodes 0, 1, 2 (the one `start_slope_row` takes its slope from): exact and
    linear, as v0 and a0 are given (no tangent). Without it the first interval's jerk was
    bounded by nothing but node 1's row: its quintic reached 4.6 jmax at t = 0 from
    (628 mm/s, +1735 mm/s^2) on tube-1450, where the heuristic planned 0.998."""
    n = geo.n_nodes
    w2 = fd_weights(geo.s[:3])[1][0]  # q'' of the quadratic through nodes 0, 1, 2
    k = geo.d1.shape[1]
    A = np.zeros((k, n))
    A[:, :3] = 0.5 * v0 * geo.d1[0, :, None] * w2[None, :]
    g = geo.d3[0] * v0**3 + 3.0 * geo.d2[0] * v0 * a0
    J = scale * jmax
    return Rows(sp.csr_matrix(A), -J - g, J - g)


def end_slope_row(geo: GridGeometry, a_end: float) -> Rows:
    """q'(s_N) / 2 = a_end: the plan ends with path acceleration a_end (backward slope)."""
    n = geo.n_nodes
    A = np.zeros((1, n))
    A[0, -3:] = 0.5 * backward_slope_weights(geo.s)
    return Rows(sp.csr_matrix(A), np.array([a_end]), np.array([a_end]))


def jerk_operator(geo: GridGeometry, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of L_k(q) = x''' q + 3/2 x'' q' + 1/2 x' q'' at the interior nodes.

    Returns (coef (N-1, 3) on (i-1, i, i+1), interior node indices).
    """
    w1, w2 = fd_weights(geo.s)
    nodes = np.arange(1, geo.n_nodes - 1)
    coef = 1.5 * geo.d2[nodes, axis, None] * w1 + 0.5 * geo.d1[nodes, axis, None] * w2
    coef[:, 1] += geo.d3[nodes, axis]
    return coef, nodes


def knot_tangent_point(q_star: np.ndarray, J: np.ndarray, knot: np.ndarray) -> np.ndarray:
    """The linearization point of a jerk row with a C1 knot's term (`jerk_rows`): q* no
    higher than J / knot, where the bound J / sqrt(q) - knot sqrt(q) on |L| reaches 0.

    Why: that bound is convex and +inf at q = 0, but its tangent at q* meets q = 0 at
    3/2 J / sqrt(q*) - knot sqrt(q*) / 2, below 0 for q* > 3 J / knot: the row then
    excluded q = 0, and with it every solution where the jump's own cap (`c1_knot_caps`)
    holds q below J / knot anyway. Measured: fuzzed random pchip paths linearized at
    their upper bounds, 14 such rows made the whole-job LP infeasible at every grid
    (`bench/fuzz_paths.py`, case 6439). At q* = J / knot the row reads knot q <= J where
    L = 0, the bound itself."""
    with np.errstate(divide="ignore"):
        top = np.where(knot > 0.0, J / knot, np.inf)
    return np.minimum(q_star, top)


def jerk_rows(
    geo: GridGeometry, jmax: np.ndarray, scale: np.ndarray, q_star: np.ndarray, q_floor: float,
    knot: np.ndarray | None = None,
) -> Rows:
    """Tangent rows +-sqrt(q*_i) L_k(q) + J q_i / (2 q*_i) <= 3/2 J at the interior nodes.

    J = scale_i jmax_k; q* is floored at q_floor (a tangent at 0 does not exist).
    knot: per node and axis (n, naxes), the checker's extra jerk per unit q at a C1 knot
    nearby (`lp.knots.knot_jumps` / dt, s^-1 / path unit^2 ...): the row then bounds
    |jerk| + knot q by J, the tangent of the convex J / sqrt(q) - knot sqrt(q) at q*:
    +-sqrt(q*) L + (J / (2 q*) + knot / 2) q <= 3/2 J - knot q* / 2 (conservative), with
    q* no higher than J / knot (`knot_tangent_point`), so that q = 0 satisfies it.
    """
    n = geo.n_nodes
    qs = np.maximum(q_star, q_floor)
    parts = []
    for k in range(geo.d1.shape[1]):
        coef, nodes = jerk_operator(geo, k)
        J = jmax[k] * scale[nodes]
        kc = np.zeros(nodes.size) if knot is None else knot[nodes, k]
        qk = knot_tangent_point(qs[nodes], J, kc)
        root = np.sqrt(qk)[:, None]
        for sign in (1.0, -1.0):
            c = sign * root * coef
            c[:, 1] += J / (2.0 * qk) + 0.5 * kc
            parts.append(Rows(_tridiagonal(c, nodes, n), np.full(nodes.size, -np.inf),
                              1.5 * J - 0.5 * kc * qk))
    parts.append(midpoint_jerk_rows(geo, jmax, scale, qs, q_floor, knot))
    return Rows.stack(parts, n)


def midpoint_operators(geo: GridGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                   np.ndarray]:
    """q, q' and q'' at the midpoints of the intervals j = 1 .. N-3 (both ends interior
    nodes) as rows on the nodes (j-1, j, j+1, j+2): the cubic Hermite interpolant of the
    nodal q and their central slopes q' (`fd_weights`), which is what the quintic
    reconstruction (`lp.profile`) follows between the nodes, to O(h^3).

    Returns (Q, DQ, DDQ, j), each operator of shape (m, 4)."""
    w1, _ = fd_weights(geo.s)
    j = np.arange(1, geo.n_nodes - 2)
    h = np.diff(geo.s)[j][:, None]
    p0 = np.zeros((j.size, 4))
    p1 = np.zeros((j.size, 4))
    p0[:, :3] = w1[j - 1]
    p1[:, 1:] = w1[j]
    e0 = np.zeros(4)
    e0[1] = 1.0
    e1 = np.zeros(4)
    e1[2] = 1.0
    Q = 0.5 * (e0 + e1)[None, :] + 0.125 * h * (p0 - p1)
    DQ = 1.5 * (e1 - e0)[None, :] / h - 0.25 * (p0 + p1)
    DDQ = (p1 - p0) / h
    return Q, DQ, DDQ, j


def midpoint_jerk_rows(geo: GridGeometry, jmax: np.ndarray, scale: np.ndarray,
                       qs: np.ndarray, q_floor: float, knot: np.ndarray | None = None
                       ) -> Rows:
    """The tangent jerk rows of `jerk_rows` at the interval midpoints (issue 13): the
    nodal rows alone let the LP cancel a large geometric jerk x_sss v^3 with the path
    jerk x_s j exactly at the nodes where x_sss changes sign between them (a sharp bend
    one or two node spacings wide, the butterfly NURBS at s = 172.9: nodal jerk 0.52 J,
    the reconstructed profile 3.7 J between the nodes, which no tightening of the nodal
    rows repaired). q = 0 satisfies these rows as well (feasibility is unchanged).
    qs: the linearization point at the nodes (floored); at a midpoint, the mean of its
    nodes'. J is the larger of the two nodes' scale times jmax (the smaller made 10 of
    test_lp_planner's 60 moving starts infeasible: `_relieve_start` relieves node 1 only).
    knot: as in `jerk_rows`, the larger of the interval's two nodes' values."""
    n = geo.n_nodes
    if geo.mid is None or n < 4:
        return Rows(sp.csr_matrix((0, n)), np.empty(0), np.empty(0))
    Q, DQ, DDQ, j = midpoint_operators(geo)
    m1, m2, m3 = (m[j] for m in geo.mid)
    known = np.all(np.isfinite(m1) & np.isfinite(m2) & np.isfinite(m3), axis=1)
    q_mid = np.maximum(0.5 * (qs[j] + qs[j + 1]), q_floor)
    sj = np.maximum(scale[j], scale[j + 1])  # a relieved start node relieves its interval
    parts = []
    for k in range(geo.d1.shape[1]):
        L = m3[:, k, None] * Q + 1.5 * m2[:, k, None] * DQ + 0.5 * m1[:, k, None] * DDQ
        J = jmax[k] * sj
        kc = np.zeros(j.size) if knot is None else np.maximum(knot[j, k], knot[j + 1, k])
        qm = knot_tangent_point(q_mid, J, kc)
        root = np.sqrt(qm)[:, None]
        for sign in (1.0, -1.0):
            c = sign * root * L + (J / (2.0 * qm) + 0.5 * kc)[:, None] * Q
            parts.append(Rows(banded(c[known], j[known] - 1, n),
                              np.full(int(known.sum()), -np.inf),
                              (1.5 * J - 0.5 * kc * qm)[known]))
    return Rows.stack(parts, n)


def nodal_jerk(geo: GridGeometry, q: np.ndarray) -> np.ndarray:
    """The (nonlinear) axis jerk sqrt(q) L_k(q) at the interior nodes, shape (N-1, naxes)."""
    out = []
    for k in range(geo.d1.shape[1]):
        coef, nodes = jerk_operator(geo, k)
        L = coef[:, 0] * q[nodes - 1] + coef[:, 1] * q[nodes] + coef[:, 2] * q[nodes + 1]
        out.append(np.sqrt(np.maximum(q[nodes], 0.0)) * L)
    return np.stack(out, axis=1)


def nodal_acceleration(geo: GridGeometry, q: np.ndarray) -> np.ndarray:
    """Axis acceleration x'' q + x' q'/2 at the interior nodes, shape (N-1, naxes)."""
    w1, _ = fd_weights(geo.s)
    nodes = np.arange(1, geo.n_nodes - 1)
    dq = w1[:, 0] * q[nodes - 1] + w1[:, 1] * q[nodes] + w1[:, 2] * q[nodes + 1]
    return geo.d2[nodes] * q[nodes, None] + 0.5 * geo.d1[nodes] * dq[:, None]


def path_jerk_operator(geo: GridGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of q''/2 at the interior nodes, on (i-1, i, i+1): the path jerk
    d3s/dt3 = sqrt(q) q''/2 per unit sqrt(q). Returns (coef (N-1, 3), node indices)."""
    _, w2 = fd_weights(geo.s)
    return 0.5 * w2, np.arange(1, geo.n_nodes - 1)


def jerk_change_rows(
    geo: GridGeometry, jmax: np.ndarray, q_star: np.ndarray, q_floor: float, kappa: float,
    skip: np.ndarray | None = None, axis_jerk: bool = False,
) -> Rows:
    """|j_i+1 - j_i| <= kappa min_k jmax_k / |x'_k| between neighbouring interior nodes
    (the change of the axis jerk's path-jerk term x'_k j within kappa jmax_k for every
    axis k), with the path jerk surrogate j_i = sqrt(q*_i) q''_i / 2 (exact at q = q*)
    and |x'_k| the mean of the two nodes' values.

    Not a machine limit but a regularizer: without it the LP's optimal vertices let the
    nodal jerk alternate between +J and -J node to node (q zig-zags, which the central
    differences of q' do not see), and any smooth profile through such nodes overshoots.
    It bounds the change of the path's own motion only (the path jerk, which the quintic
    reconstruction has to follow between the nodes), not of the axis jerk's geometric
    terms x_sss v^3 and 3 x_ss v a: the check evaluates those on the exact geometry, so
    they carry no reconstruction error. A row on the whole axis jerk (before issue 13's
    fix) also held the change of x_sss v^3 to 0.15 jmax per node, and where x_sss turns
    within a few nodes (a dome's pole, a helix's turnaround) it forced the feed down:
    the polar dome 2.43 s against 2.14 s, the short helix 2.61 s against 2.24 s, either
    without a repair (the fine-grid reference LP: 1.70 s, 2.15 s).
    skip: node indices (rest points) whose neighbours get no such row: next to a fixed
    q = 0 the linearized row can pin the neighbour to 0 as well (a stalled interval).
    axis_jerk: the rows before issue 13's fix instead, |j_k,i+1 - j_k,i| <= kappa jmax_k
    per axis on the whole axis jerk surrogate sqrt(q*) L_k(q) (`jerk_operator`), for
    OSQP: its ADMM did not converge on n-butterfly's first jerk pass with the path-jerk
    rows (10-18 % outside the limit rows after 30000 iterations).
    """
    n = geo.n_nodes
    root = np.sqrt(np.maximum(q_star, q_floor))
    nodes = np.arange(1, n - 1)
    m = nodes.size - 1
    keep = np.ones(m, dtype=bool)
    if skip is not None and skip.size:
        near = np.zeros(n + 2, dtype=bool)
        for off in (-1, 0, 1):
            near[np.clip(skip + off, 0, n - 1)] = True
        keep = ~(near[nodes[:-1]] | near[nodes[1:]])

    def rows_of(coef: np.ndarray, rows: np.ndarray, bound: np.ndarray) -> Rows:
        """Row r (of the kept `rows`): coef's j at node r+2 minus at node r+1, on
        columns r .. r+3, within +-bound."""
        c = root[nodes, None] * coef
        band = np.zeros((m, 4))
        band[:, 1:] += c[1:]
        band[:, :3] -= c[:-1]
        return Rows(banded(band[rows], nodes[:-1][rows] - 1, n), -bound, bound)

    if axis_jerk:
        return Rows.stack([rows_of(jerk_operator(geo, k)[0], keep,
                                   np.full(int(keep.sum()), kappa * jmax[k]))
                           for k in range(geo.d1.shape[1])], n)
    # one row per node pair, at the axis that binds (per-axis rows would be parallel)
    tangent = 0.5 * (np.abs(geo.d1[nodes[:-1]]) + np.abs(geo.d1[nodes[1:]]))
    with np.errstate(divide="ignore"):
        path_j = np.min(jmax[None, :] / tangent, axis=1)  # path jerk at the axis limits
    keep &= np.isfinite(path_j)
    return rows_of(path_jerk_operator(geo)[0], keep, kappa * path_j[keep])

