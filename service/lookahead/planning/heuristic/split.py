"""Planning segments split where their constant cruise cap loses time under the feed-limit
curve.

A planning segment cruises at most at V = the minimum of the feed limit over its cells
(`path_limits.segment_budgets`). Where the limit curve slopes or waves inside a segment (a
long stroke starting at a slightly lower limit, a circle under per-axis limits) that cap
throws away the area between it and the curve. The time a segment loses to its cap is
    loss = sum_c L_c (1 / V - 1 / vlim_c)      (seconds; L_c cell length, vlim_c its limit),
and a segment whose loss is large is cut into runs of cells below / above `step` V: the
low runs keep a cap within `step` of their limit, the high runs get a cap at least `step`
higher and are split again where they still lose. Units: path units (mm) and seconds.
"""

from __future__ import annotations

import itertools

import numpy as np


def split_by_loss(edges: np.ndarray, vlim: np.ndarray, starts: np.ndarray,
                  rel_loss: float, abs_loss: float, step: float,
                  max_depth: int = 8) -> np.ndarray:
    """Refined segment starts (cell indices, as `path_limits.choose_segments` returns).

    edges: (ncell + 1,) cell boundaries (s); vlim: (ncell,) feed limit per cell;
    starts: (nseg + 1,) initial segment starts. A segment is split when its loss exceeds
    both `rel_loss` times its time at the limit and `abs_loss` seconds; at most
    `max_depth` nested splits per segment (bounds the segment count on wiggly curves)."""
    length = np.diff(edges)
    inv = length / np.minimum(vlim, 1e300)
    keep = _clearly_kept(length, inv, vlim, starts, rel_loss, abs_loss)
    out = [0]
    for k, (a0, b0) in enumerate(itertools.pairwise(starts.tolist())):
        if keep[k]:
            out.append(b0)
            continue
        stack = [(a0, b0, 0)]
        while stack:
            a, b, depth = stack.pop()
            v = vlim[a:b]
            V = float(np.min(v))
            t_lim = float(np.sum(inv[a:b]))
            loss = float(np.sum(length[a:b])) / V - t_lim if V > 0 else 0.0
            if depth >= max_depth or b - a < 2 or not (loss > rel_loss * t_lim
                                                       and loss > abs_loss):
                out.append(b)
                continue
            low = v < step * V
            cut = np.nonzero(low[1:] != low[:-1])[0] + 1 + a
            bounds = [a, *cut.tolist(), b]
            parts = [(bounds[i], bounds[i + 1], depth + 1) for i in range(len(bounds) - 1)]
            stack.extend(reversed(parts))
    return np.asarray(out, dtype=int)


def _clearly_kept(length: np.ndarray, inv: np.ndarray, vlim: np.ndarray, starts: np.ndarray,
                  rel_loss: float, abs_loss: float) -> np.ndarray:
    """(nseg,) True for the segments of `starts` that `split_by_loss` keeps whole whatever
    the rounding of its sums: their loss, from all segments' sums at once (`reduceat`:
    another summation order than `np.sum`), lies below a split threshold by more than
    1e-9 of the times involved (rounding of sums over < 10^6 cells stays far below). The
    others go through the exact test, so the result is the same as testing every segment
    (and the per-segment numpy calls were most of the cost on hundreds of segments)."""
    a, b = starts[:-1], starts[1:]
    nonempty = b > a
    keep = ~nonempty | (b - a < 2)
    if not nonempty.any():
        return keep
    first = a[nonempty]
    V = np.minimum.reduceat(vlim, first)
    t_lim = np.add.reduceat(inv, first)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cap = np.add.reduceat(length, first) / V
        loss = t_cap - t_lim
        tol = 1e-9 * (np.abs(t_cap) + np.abs(t_lim))
        clear = (loss < rel_loss * t_lim - tol) | (loss < abs_loss - tol)
    keep[nonempty] |= (V > 0) & np.isfinite(tol) & clear
    return keep
