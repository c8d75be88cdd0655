"""A simplex basis carried from one window's LP to the next by node position.

Consecutive windows of a job overlap on most of their path (re-gridded: the nodes differ
beyond a seam's head), and their rows are stacked kind by kind in the same order
(`lp.rows`), so the last window's optimal basis says, for most of the new LP, which feeds
sat at their caps and which limit rows were binding. `map_basis` transfers it: a column
takes the status of the column at the nearest node s, a row the status of the row with
the same `row_keys` key there; fresh columns start at their lower bound, fresh rows with
their slack basic. The count of basic variables is then off by a few at the window's
ends, which HiGHS's alien-basis handling repairs (it factors the basic set and completes
or trims it with slacks).

Written here because no library maps a basis between LPs of different size. The rows'
keys are `solve.row_keys`; `match_rows` also maps OSQP's warm start across windows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a carried basis is used when at least this share of the new LP's rows have a match in
#: the old one (the velocity+acceleration and jerk passes are told apart before, by
#: `solve._kind`). Trades a start from a mostly foreign basis against a cold one: 0.5 left
#: cam-fp-hel45-D30's windows that overlap their predecessor by 35-50 % cold, 0.1 carried
#: them (its cold jerk LPs 5,155 -> 3,792 and 6,566 -> 3,259 iterations); measured on that
#: path only, then on the corpus as a whole (README, stop 42)
MIN_ROW_SHARE = 0.1


@dataclass
class CarriedBasis:
    """One optimal solve's basis (HiGHS status codes as ints) with its node positions s
    (path units) and its rows' keys."""

    nodes: np.ndarray
    keys: np.ndarray
    col_status: np.ndarray
    row_status: np.ndarray


def match_rows(keys_new: np.ndarray, keys_old: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (new, old) of the rows whose keys (`solve.row_keys`: s, rank, entries) occur
    in both, vectorized (a window has ~12,000 rows). Keys are unique within an LP; a key
    with a NaN (a node off the grid) matches nothing."""
    empty = np.empty(0, dtype=int)
    if keys_new.size == 0 or keys_old.size == 0:
        return empty, empty

    def packed(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = np.ascontiguousarray(keys, dtype=float) + 0.0  # -0.0 -> 0.0: equal bytes
        ok = np.flatnonzero(~np.isnan(k).any(axis=1))
        k = np.ascontiguousarray(k[ok])
        return k.view(np.dtype((np.void, k.dtype.itemsize * k.shape[1]))).ravel(), ok

    (a, ok_new), (b, ok_old) = packed(keys_new), packed(keys_old)
    if a.size == 0 or b.size == 0:
        return empty, empty
    _, new, old = np.intersect1d(a, b, assume_unique=False, return_indices=True)
    return ok_new[new], ok_old[old]


def nearest_nodes(nodes_new: np.ndarray, nodes_old: np.ndarray) -> np.ndarray:
    """Per new node, the index of the nearest old node, or -1 outside the old grid's span
    (NaN nodes, e.g. elastic slack columns, are outside). Windows re-grid their path, so
    a node of the new LP rarely sits exactly on one of the old."""
    out = np.full(nodes_new.size, -1, dtype=np.int64)
    if nodes_new.size == 0 or nodes_old.size == 0:
        return out
    old_ok = np.isfinite(nodes_old)
    finite = nodes_old[old_ok]
    if finite.size == 0:
        return out
    idx = np.flatnonzero(old_ok)
    j = np.clip(np.searchsorted(finite, nodes_new), 0, finite.size - 1)
    j_left = np.maximum(j - 1, 0)
    j = np.where(np.abs(finite[j_left] - nodes_new) < np.abs(finite[j] - nodes_new), j_left, j)
    span = (nodes_new >= finite[0]) & (nodes_new <= finite[-1])
    out[span] = idx[j[span]]
    return out


def map_basis(carried: CarriedBasis, nodes: np.ndarray, keys: np.ndarray,
              lower_code: int, basic_code: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Column and row status codes for an LP with these nodes (s, path units) and row keys,
    or None when too few rows match (`MIN_ROW_SHARE`). A column takes the status of the
    old column at the nearest node; a row that of the old row with its key once its first
    node is moved onto that nearest node. lower_code / basic_code: HiGHS's codes for "at
    lower bound" and "basic" (fresh columns, fresh rows)."""
    near = nearest_nodes(nodes, carried.nodes)
    snapped = keys.astype(float, copy=True)
    first = nearest_nodes(keys[:, 0], carried.nodes)
    snapped[:, 0] = np.where(first >= 0, carried.nodes[np.maximum(first, 0)], np.nan)
    new_r, old_r = match_rows(snapped, carried.keys)
    if new_r.size < MIN_ROW_SHARE * keys.shape[0]:
        return None
    cols = np.full(nodes.size, lower_code, dtype=np.int64)
    hit = near >= 0
    cols[hit] = carried.col_status[near[hit]]
    rows = np.full(keys.shape[0], basic_code, dtype=np.int64)
    rows[new_r] = carried.row_status[old_r]
    return cols, rows
