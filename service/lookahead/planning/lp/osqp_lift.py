"""The feed LP's rows rewritten on finite differences of the variables, for OSQP.

The LP's rows are narrow bands on neighbouring nodes (acceleration and jerk rows on three
nodes, jerk-change rows on four: `lp.rows`) whose coefficients nearly cancel: a
jerk-change row is close to a third difference of z with large coefficients and a bound
~1e-3 of them. ADMM (OSQP) on such rows crawls: measured on the first jerk pass of
w-hel-R50-a45-sine-2mm-short, c-cycloid-near-cusp-a0p995 and w-polar-dome-R30-a5-0p5mm
it did not converge in 20000 iterations for any mu, rho, sigma, alpha, eps or Ruiz
iterations tried, and not even from HiGHS's optimum as its start.

Rewritten on the forward differences d_k (d_0 = z, d_k[i] = d_k-1[i+1] - d_k-1[i]) with
the chain of equalities as extra rows, each band row becomes a short row whose largest
coefficient sits on the difference it bounds (the multiple-shooting form of an optimal
control problem, in which OSQP is at home). A row on columns c .. c+w-1 with
coefficients a_j is exactly sum_k b_k d_k[c], b_k = sum_j a_j C(j, k) (Newton's forward
difference formula), so the lifted problem has the same feasible set and optimum in z.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np
import scipy.sparse as sp

#: the highest difference order the lift introduces (rows span at most ORDER + 1 nodes;
#: wider rows stay on z unchanged)
ORDER = 3


@dataclass(frozen=True)
class Lifted:
    """Lifted rows: `rows` (on all N lifted variables, CSC) hold the band rows rewritten,
    `chain` the equalities d_k[i] - d_k-1[i+1] + d_k-1[i] = 0. The first n variables are z;
    `offsets[k]` is where d_k starts."""

    rows: sp.csc_matrix
    chain: sp.csc_matrix
    n: int
    offsets: np.ndarray

    @property
    def size(self) -> int:
        return int(self.offsets[-1])

    def extend(self, z: np.ndarray) -> np.ndarray:
        """The lifted vector (z and its differences) of z."""
        parts, d = [z], z
        for _ in range(self.offsets.size - 2):
            d = np.diff(d)
            parts.append(d)
        return np.concatenate(parts)


def column_range(A: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row of A (CSR): its first and last column with an entry, and whether it has
    any (first = last = 0 for an empty row)."""
    m = A.shape[0]
    filled = np.diff(A.indptr) > 0
    first = np.zeros(m, dtype=int)
    last = np.zeros(m, dtype=int)
    if A.nnz:
        starts = A.indptr[:-1][filled]
        first[filled] = np.minimum.reduceat(A.indices, starts)
        last[filled] = np.maximum.reduceat(A.indices, starts)
    return first, last, filled


def lift_rows(A: sp.csr_matrix, order: int = ORDER, chain_weight: bool = True) -> Lifted:
    """`A` (m x n) rewritten on z and its forward differences up to `order`."""
    A = A.tocsr()
    m, n = A.shape
    order = max(0, min(order, n - 1))
    offsets = np.cumsum([0] + [n - k for k in range(order + 1)])
    counts = np.diff(A.indptr)
    first, last, filled = column_range(A)
    span = last - first + 1
    band = filled & (span <= order + 1)
    row_of = np.repeat(np.arange(m), counts)
    in_band = band[row_of]
    # dense band coefficients a[r, j] on columns first[r] + j
    width = order + 1
    dense = np.zeros((m, width))
    j = A.indices - first[row_of]
    dense[row_of[in_band], j[in_band]] = A.data[in_band]
    pascal = np.array([[comb(jj, k) for k in range(width)] for jj in range(width)], float)
    b = dense @ pascal  # b[r, k]: coefficient on d_k[first[r]]
    br, bk = np.nonzero(b * band[:, None])
    rows_i = [br, row_of[~in_band]]
    cols_i = [offsets[bk] + first[br], A.indices[~in_band]]
    vals = [b[br, bk], A.data[~in_band]]
    N = int(offsets[-1])
    R = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows_i), np.concatenate(cols_i))),
                      shape=(m, N))
    er, ec, ev = [], [], []
    e = 0
    for k in range(1, order + 1):
        i = np.arange(n - k)
        rows_k = e + i
        er += [rows_k, rows_k, rows_k]
        ec += [offsets[k] + i, offsets[k - 1] + i + 1, offsets[k - 1] + i]
        ev += [np.ones(i.size), -np.ones(i.size), np.ones(i.size)]
        e += i.size
    chain = sp.csc_matrix(
        (np.concatenate(ev) if ev else np.empty(0),
         (np.concatenate(er) if er else np.empty(0, int),
          np.concatenate(ec) if ec else np.empty(0, int))), shape=(e, N))
    if chain_weight and e:
        # a chain residual r on d_k moves a lifted row by b_k r: weigh each equality by
        # the largest coefficient a row has on its d_k, so that OSQP's tolerance on the
        # chain means the same as on the rows
        peak = np.asarray(abs(R).max(axis=0).todense()).ravel()
        w = np.maximum(peak[np.concatenate(ec[::3])], 1.0)
        chain = sp.diags(w) @ chain
    return Lifted(R, chain.tocsc(), n, offsets)
