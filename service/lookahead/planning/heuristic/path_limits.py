"""Path limits for the heuristic planner: the geometry on a grid of cells, the feed limit
per point, planning segments chosen by geometry, and per-segment budgets.

Frames and units: s is arc length (path units, mm), feeds are path units/s; x_s, x_ss,
x_sss are axis derivatives w.r.t. s (axis unit per path unit^n). Along the path, axis i has
  velocity x_s v,  acceleration x_ss v^2 + x_s a,  jerk x_sss v^3 + 3 x_ss v a + x_s j.

A cell is a stretch of the path between consecutive "nodes" (window ends, corners, feed-cap
breaks, path knots), cut further when longer than a maximum cell length. Every cell is
evaluated at three budget points (just inside both ends and the middle) and two check points
(quarter points) that the planner uses to verify the result between budget points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lookahead.geometry.base import Path, arc_length_derivatives
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedCap

#: fractions of a cell where it is evaluated: budget points, then check points
BUDGET_FRACTIONS = np.array([1e-7, 0.5, 1.0 - 1e-7])
CHECK_FRACTIONS = np.array([0.25, 0.75])
_TINY = 1e-12


@dataclass(frozen=True)
class BudgetShares:
    """How each axis limit is shared out when bounding the feed by geometry.

    centripetal: share of amax that |x_ss| v^2 may take (the rest is for path acceleration).
    jerk_geometric: share of jmax that |x_sss| v^3 may take.
    jerk_coupling: share of jmax that 3 |x_ss| v a may take.
    c1_knot: share of jmax * dt that the acceleration jump |dx_ss| v^2 at a C1 knot may take
    (the cells beside the knot keep 1 - 3/4 of it for the rest). Trades the feed through
    the knot against the jerk around it; swept by bench/c1_knot_share.py on the corpus's
    two C1 paths and ten generated ones (bench/results/c1_knot_share.json): 0.75 is at
    worst 1.105x the best share per path (geometric mean 1.025x), 0.25 up to 1.46x
    (c-rand3-xyz-pchip 17.31 -> 12.75 s, the pchip helix 8.56 -> 7.76 s), 0 violations
    at every share.
    velocity: share of vmax that |x_s| v may take at the budget points (below 1: |x_s| peaks
    between them; at 1.0 the sampled X velocity of Fourier paths exceeded vmax by 1e-8 to
    4e-8 relative, with fine and coarse bands; 1e-4 below costs 0.01 % on X-bound strokes).
    headroom: share of amax and jmax the segment budgets use in all (below 1: a brake at
    the jerk budget on a straight stroke, planned to the full limits, was sampled at
    jmax (1 + 1e-7) by the checker in replans of the tubes; the paper's heuristic too).
    """

    centripetal: float = 0.6
    jerk_geometric: float = 0.3
    jerk_coupling: float = 0.3
    c1_knot: float = 0.75
    velocity: float = 0.9999
    headroom: float = 0.9999


@dataclass(frozen=True)
class PathGrid:
    """Cells over [s_begin, s_end] and the geometry at their budget and check points.

    edges: (ncell + 1,) cell boundaries. xs/xss/xsss: (ncell, npoints, naxes) at the points
    BUDGET_FRACTIONS + CHECK_FRACTIONS of each cell. jerk_scale: (ncell,) factor <= 1 on
    jmax for cells next to a C1 knot. c1_cap: (ncell,) feed cap from C1 knots (inf if none).
    corner_after: (ncell,) True where the path has a corner at the cell's right end.
    lead_cells: how many cells the leading node interval for the start state
    (`lead_length`) has (0: none).
    """

    edges: np.ndarray
    s: np.ndarray
    xs: np.ndarray
    xss: np.ndarray
    xsss: np.ndarray
    jerk_scale: np.ndarray
    c1_cap: np.ndarray
    corner_after: np.ndarray
    lead_cells: int = 0
    #: arrays the feed limit and budget passes reuse (`feed_limit`, `_budget_terms`)
    _terms: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def ncells(self) -> int:
        return int(self.edges.size - 1)


def _inside(values: np.ndarray, lo: float, hi: float, pad: float) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    return values[(values > lo + pad) & (values < hi - pad)]


def end_corners(corners: np.ndarray, lo: float, hi: float, pad: float) -> tuple[bool, bool]:
    """Whether a corner of the path lies at arc length lo, and at hi (within pad).

    Why: at a cusp the chain rule's x_ss and x_sss beside the corner are cancellation
    (`_retreat_from_corners`); a request from rest at a cusp of a pchip walk read them at
    its first budget point and planned its 15 mm from one corner to the next in 4248 s
    (7.6 s from 1e-6 further on), and the LP's rest splice, which plans exactly such
    stretches, spent 85 s verifying that plan (`bench/fuzz_paths.py` case (3035, 2, 11,
    0.979, -0.883, 'pchip'))."""
    c = np.asarray(corners, dtype=float)
    return bool(np.any(np.abs(c - lo) <= pad)), bool(np.any(np.abs(c - hi) <= pad))


def s_derivatives_at_u(path: Path, u: np.ndarray) -> tuple[np.ndarray, ...]:
    """sigma = ds/du (n,) and x_s, x_ss, x_sss (n, naxes) at parameters u.

    The chain rule of `Path.eval_s`, applied at given u: the grid is laid out in u, which
    avoids inverting u(s) (90 % of the cost of eval_s) for thousands of points."""
    fast = getattr(path, "eval_u_derivatives", None)  # skips the position if it can
    d = [None, *fast(u, 3)] if fast is not None else path.eval_u(u, order=3)
    return arc_length_derivatives(d, path.path_scale)


def _cell_arc_lengths(sigma: np.ndarray, du: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc length of each cell and of its points from the cell start, from the speed
    sigma at the fractions (0, .5, 1, .25, .75): composite Simpson on the quarter points,
    and 3-point quadrature for the partial lengths (hand-written: the speeds are already
    known, so no new evaluations are needed)."""
    s0, s2, s4, s1, s3 = (sigma[:, i] for i in range(5))
    first_half = du / 12.0 * (s0 + 4.0 * s1 + s2)
    second_half = du / 12.0 * (s2 + 4.0 * s3 + s4)
    quarter = du / 48.0 * (5.0 * s0 + 8.0 * s1 - s2)
    three_quarter = first_half + du / 48.0 * (5.0 * s2 + 8.0 * s3 - s4)
    total = first_half + second_half
    partial = np.stack([np.zeros_like(du), first_half, total, quarter, three_quarter], axis=1)
    return total, partial


@dataclass(frozen=True)
class _Cells:
    """Cells in u (start u0, width du, node interval) and the geometry at their points:
    sigma (ncell, npoints), xs/xss/xsss (ncell, npoints, naxes)."""

    u0: np.ndarray
    du: np.ndarray
    node: np.ndarray
    sigma: np.ndarray
    xs: np.ndarray
    xss: np.ndarray
    xsss: np.ndarray


def _evaluate_cells(path: Path, u0: np.ndarray, du: np.ndarray, node: np.ndarray) -> _Cells:
    fractions = np.concatenate([BUDGET_FRACTIONS, CHECK_FRACTIONS])
    u = u0[:, None] + du[:, None] * fractions[None, :]
    sigma, xs, xss, xsss = s_derivatives_at_u(path, u.ravel())
    shape = (*u.shape, path.naxes)
    return _Cells(u0, du, node, sigma.reshape(u.shape),
                  *(x.reshape(shape) for x in (xs, xss, xsss)))


#: a cell whose path speed sigma = ds/du varies more than this ratio over its points is
#: split into REFINE_SPLIT cells, up to REFINE_LEVELS times
REFINE_RATIO = 1.2
REFINE_SPLIT = 4
REFINE_LEVELS = 10


def _refine_cells(path: Path, cells: _Cells, corner_node: np.ndarray) -> _Cells:
    """Split cells where the geometry in s is not resolved by the cell's points.

    Within a knot interval x(u) is a polynomial, smooth on the interval's scale; all
    sharper variation of x_s, x_ss, x_sss comes from the chain rule through sigma(u),
    which dips where the path nearly reverses (near-cusps: x_sss can grow by orders of
    magnitude within a cell, and a peak between points escapes the verification). A cell
    whose sigma varies by less than REFINE_RATIO over its points resolves the dip, so
    cells are split until that holds (a true cusp, sigma = 0, stops at REFINE_LEVELS).

    Cells next to a corner (`corner_node`: (nnodes,) True where a node is a corner) are
    left alone: the machine stops there, and where the corner is a cusp of the
    parameterization (sigma -> 0 at the knot, e.g. pchip with both axes at an extremum)
    the chain rule is pure cancellation close to it, so finer cells would only see noise."""
    for _ in range(REFINE_LEVELS):
        lo, hi = np.min(cells.sigma, axis=1), np.max(cells.sigma, axis=1)
        node = cells.node
        first = np.concatenate([[True], node[1:] != node[:-1]])
        last = np.concatenate([node[1:] != node[:-1], [True]])
        at_corner = (first & corner_node[node]) | (last & corner_node[node + 1])
        sharp = (hi > REFINE_RATIO * lo) & ~at_corner
        if not np.any(sharp):
            break
        idx = np.nonzero(sharp)[0]
        du = np.repeat(cells.du[idx] / REFINE_SPLIT, REFINE_SPLIT)
        u0 = (np.repeat(cells.u0[idx], REFINE_SPLIT)
              + du * np.tile(np.arange(REFINE_SPLIT), idx.size))
        fine = _evaluate_cells(path, u0, du, np.repeat(cells.node[idx], REFINE_SPLIT))
        # cells stay ordered in u: each split cell is replaced by its parts in place
        keep = np.nonzero(~sharp)[0]
        order = np.argsort(np.concatenate([keep, np.repeat(idx, REFINE_SPLIT)]), kind="stable")
        cells = _Cells(*(np.concatenate([getattr(cells, f)[keep], getattr(fine, f)])[order]
                         for f in ("u0", "du", "node", "sigma", "xs", "xss", "xsss")))
    return cells


def lead_length(v0: float, a0: float, jerk: float) -> float:
    """Length (path units) of a leading cell in which a start state (v0 > 0, a0 < 0:
    decelerating) at path jerk `jerk` turns its acceleration to 0: LEAD_FACTOR times the
    distance of that turn and of the rise back to v0 (0 for a start that is not
    decelerating).

    A planning segment's jerk budget falls with its cruise cap, and a start on a brake to
    rest (a replan from the end of the last plan's window) turns only under at least the
    jerk a0^2 / (2 v0) of that brake; where the first segment's budget is lower, the
    planner caps the leading cell at the start feed (which raises its jerk budget), where a
    cap on the whole first segment made it crawl (cam-style path: 123 s from v0 = 0.46)."""
    if not (v0 > 0.0 and a0 < 0.0 and jerk > 0.0):
        return 0.0
    t1 = -a0 / jerk
    v1 = max(v0 - a0 * a0 / (2.0 * jerk), 0.0)
    # (a start that would stop before a = 0 at this jerk: an overestimate of its stop)
    d1 = max(v0 * t1 + a0 * t1 * t1 / 2.0 + jerk * t1**3 / 6.0, 0.0)
    d2 = (v0 + v1) * math.sqrt((v0 - v1) / jerk)  # back to v0: (v0 + v1) / 2 * 2 sqrt(dv / J)
    return LEAD_FACTOR * (d1 + d2)


#: path jerk assumed for the leading cell's length, as a share of min jmax / |x_s| at the
#: start (about the budget left beside the coupling share 3 |x_ss| v a at a low cap; a
#: lower share: a longer leading cell), and the cell's length in those distances (the
#: time spent in the cell below the start feed is about this many times the motion's;
#: 1.5 with 0.6 was too short for some replans on the braking below). Measured on
#: replans from the brakes to rest of cam-style-R50-a45-L200
LEAD_JERK_SHARE = 0.6
LEAD_FACTOR = 2.0


def build_grid(path: Path, s_begin: float, s_end: float, dt: float, limits: AxisLimits,
               shares: BudgetShares, feed_cap: FeedCap | None = None,
               max_cell: float | None = None,
               start: tuple[float, float] | None = None) -> PathGrid:
    """Cells and their geometry; cells are at most `max_cell` long (default: the path
    length / 2000: a fixed length, so windows of one path share their cell layout).

    Cells are laid out in u between nodes whose arc length is exact (window ends, corners,
    knots, feed-cap breaks); arc lengths inside a node interval come from the speeds at the
    cell points and are rescaled to the node interval's exact length. `start` (feed,
    acceleration at s_begin): a decelerating start gets a short leading cell
    (`lead_length`)."""
    span = s_end - s_begin
    pad = _TINY * max(span, 1.0)
    all_corners = path.corners_s()
    corners = _inside(all_corners, s_begin, s_end, pad)
    # a request may start or end at a corner (a rest between two stops, the LP's rest
    # splice): its end cells get the corner treatment too (`end_corners`)
    begins_at, ends_at = end_corners(all_corners, s_begin, s_end, pad)
    knots = _inside(path.breakpoints_s(), s_begin, s_end, pad)
    caps = _inside(feed_cap.s_breaks, s_begin, s_end, pad) if feed_cap is not None else []
    nodes = np.unique(np.concatenate([[s_begin, s_end], corners, knots, caps]))
    nodes_u = _u_of_nodes(path, nodes)
    lead = 0.0
    if start is not None and start[0] > 0.0 and start[1] < 0.0:
        _, xs0, _, _ = s_derivatives_at_u(path, nodes_u[:1])
        with np.errstate(divide="ignore"):
            jerk = LEAD_JERK_SHARE * float(np.min(limits.jmax / np.abs(xs0[0])))
        lead = lead_length(start[0], start[1], jerk)
        # only well inside the first node interval (else its node already is near)
        if lead > pad and s_begin + lead < nodes[0] + 0.9 * (nodes[1] - nodes[0]):
            node = np.array([s_begin + lead])
            nodes = np.concatenate([nodes[:1], node, nodes[1:]])
            nodes_u = np.concatenate([nodes_u[:1], path.u_of_s(node), nodes_u[1:]])
        else:
            lead = 0.0
    c1_s, c1_caps = np.empty(0), np.empty(0)
    if path.continuity() < 2:
        nodes, nodes_u, c1_s, c1_caps = _c1_knot_zones(path, nodes, nodes_u, knots, corners,
                                                       dt, limits, shares)
    lengths = np.diff(nodes)
    max_cell = path.length / 2000.0 if max_cell is None else max_cell
    nsub = np.maximum(1, np.ceil(lengths / max_cell)).astype(int)
    cell_node = np.repeat(np.arange(lengths.size), nsub)
    offset = np.arange(cell_node.size) - np.repeat(np.cumsum(nsub) - nsub, nsub)
    du = (nodes_u[1:] - nodes_u[:-1])[cell_node] / nsub[cell_node]
    u0 = nodes_u[cell_node] + du * offset
    corner_node = np.isin(nodes, corners)
    corner_node[0] |= begins_at
    corner_node[-1] |= ends_at
    cells = _refine_cells(path, _evaluate_cells(path, u0, du, cell_node), corner_node)
    u0, du, cell_node = cells.u0, cells.du, cells.node
    sigma, xs, xss, xsss = cells.sigma, cells.xs, cells.xss, cells.xsss
    total, partial = _cell_arc_lengths(sigma, du)
    first_cell = np.searchsorted(cell_node, np.arange(lengths.size))
    # rescale each node interval's cells to its exact length
    approx = np.add.reduceat(total, first_cell)
    scale = np.where(approx > 0, lengths / np.where(approx > 0, approx, 1.0), 1.0)[cell_node]
    total, partial = total * scale, partial * scale[:, None]
    cell_start = np.concatenate([[0.0], np.cumsum(total)])
    node_start = cell_start[first_cell][cell_node]
    edges_rel = cell_start[:-1] - node_start
    edges = np.concatenate([nodes[cell_node] + edges_rel, [s_end]])
    # `partial` is at fractions (0, .5, 1, .25, .75); move the ends to the inset points
    s = edges[:-1, None] + partial
    s[:, 0] += BUDGET_FRACTIONS[0] * total
    s[:, 2] -= (1.0 - BUDGET_FRACTIONS[2]) * total

    ncell = du.size
    jerk_scale = np.ones(ncell)
    c1_cap = np.full(ncell, np.inf)
    if c1_s.size:
        # the two cells either side of a C1 knot: feed cap and less jerk for the rest;
        # the FD jerk adds up to 3/4 of the acceleration jump over dt (kernel peak)
        right = np.searchsorted(edges, c1_s - pad)
        for cells in (right, right - 1):
            ok = (cells >= 0) & (cells < ncell)
            c1_cap[cells[ok]] = np.minimum(c1_cap[cells[ok]], c1_caps[ok])
            jerk_scale[cells[ok]] = 1.0 - 0.75 * shares.c1_knot
    corner_after = np.zeros(ncell, dtype=bool)
    corner_before = np.zeros(ncell, dtype=bool)
    if corners.size:
        corner_after[np.searchsorted(edges, corners - pad) - 1] = True
        corner_before[np.searchsorted(edges, corners - pad)] = True
    # (an end corner is not marked `corner_after`: the request's ends are states of
    # their own, which the planner and its verification hold already)
    corner_before[0] |= begins_at
    retreat_after = corner_after.copy()
    retreat_after[-1] |= ends_at
    if corner_before.any() or retreat_after.any():
        _retreat_from_corners(s, xs, xss, xsss, corner_before, retreat_after)
    lead_cells = int(np.count_nonzero(cell_node == 0)) if lead > 0.0 else 0
    return PathGrid(edges, s, xs, xss, xsss, jerk_scale, c1_cap, corner_after, lead_cells)


def _retreat_from_corners(s: np.ndarray, xs: np.ndarray, xss: np.ndarray, xsss: np.ndarray,
                          corner_before: np.ndarray, corner_after: np.ndarray) -> None:
    """In place: a cell touching a corner takes its corner-side budget point from the
    check point a quarter cell away from the corner (index 3 for a corner at the cell's
    start, 4 for one at its end).

    The machine comes to rest at a corner, so the feed there is 0 whatever the geometry;
    but at a cusp x_ss ~ d^-1/2 and x_sss ~ d^-3/2 at distance d from it (worse still in
    floating point, by cancellation in the chain rule), and a budget point 1e-7 of a cell
    from the corner would cap the whole cell at a crawl. In the last quarter cell the stop
    itself keeps the axis terms small (v ~ d^2/3 in a jerk-limited stop, so x_sss v^3 and
    x_ss v^2 vanish as d -> 0); the planner still verifies the quarter point, and the
    finite-difference checker judges the rest."""
    for cells, budget, check in ((corner_before, 0, 3), (corner_after, 2, 4)):
        for x in (s, xs, xss, xsss):
            x[cells, budget] = x[cells, check]


def _u_of_nodes(path: Path, nodes: np.ndarray) -> np.ndarray:
    """u at the node arc lengths: exact from the path's knots where a node is a knot
    (paths with a `breakpoints_u` accessor), u_of_s for the rest (window ends, caps)."""
    knots_u = getattr(path, "breakpoints_u", None)
    if knots_u is None:
        return path.u_of_s(nodes)
    knots_s = path.breakpoints_s()
    idx = np.clip(np.searchsorted(knots_s, nodes), 0, knots_s.size - 1)
    is_knot = knots_s[idx] == nodes
    u = np.empty_like(nodes)
    u[is_knot] = knots_u()[idx[is_knot]]
    if not np.all(is_knot):
        u[~is_knot] = path.u_of_s(nodes[~is_knot])
    return u


def _c1_knot_zones(path: Path, nodes: np.ndarray, nodes_u: np.ndarray, knots: np.ndarray,
                   corners: np.ndarray, dt: float, limits: AxisLimits, shares: BudgetShares):
    """Feed caps sqrt(share * jmax * dt / |jump of x_ss|) at the C1 knots, each confined
    to a small zone of +-4 samples at the cap around its knot by two extra nodes, so the
    cap does not depend on how the rest of the window is cut into cells.

    Returns the nodes and their u with the zone ends added, and the capped knots' s, caps.
    """
    inner = np.isin(nodes, knots) & ~np.isin(nodes, corners)
    idx = np.nonzero(inner)[0]
    if not idx.size:
        return nodes, nodes_u, np.empty(0), np.empty(0)
    du = 1e-9 * np.minimum(nodes_u[idx] - nodes_u[idx - 1], nodes_u[idx + 1] - nodes_u[idx])
    _, _, left, _ = s_derivatives_at_u(path, nodes_u[idx] - du)
    sigma, _, right, _ = s_derivatives_at_u(path, nodes_u[idx] + du)
    jump = np.abs(right - left)
    # a jump is rounding below 1e-7 of its own knot's |x_ss| (per knot: one knot where the
    # parametrization nearly stops, sigma ~ 1e-3, has |x_ss| ~ 1e6 and made every other
    # knot's jump "rounding" when the scale was the window's largest: a pchip path cruised
    # through its C1 knots at 6x their caps, 12x jmax in the checker)
    typical = np.max(np.abs(np.concatenate([left, right], axis=1)), axis=1, keepdims=True) \
        + 1.0 / max(np.ptp(nodes), _TINY)
    jump = np.where(jump > 1e-7 * typical, jump, 0.0)
    with np.errstate(divide="ignore"):
        cap = np.min(np.sqrt(shares.c1_knot * limits.jmax * dt / jump), axis=1)
    keep = np.isfinite(cap)
    idx, cap, sigma = idx[keep], cap[keep], sigma[keep]
    if not idx.size:
        return nodes, nodes_u, np.empty(0), np.empty(0)
    room = 0.25 * np.minimum(nodes[idx] - nodes[idx - 1], nodes[idx + 1] - nodes[idx])
    half = np.minimum(4.0 * cap * dt, room)
    # zone ends: u from the local speed, then their exact s from s(u)
    extra_u = np.concatenate([nodes_u[idx] - half / sigma, nodes_u[idx] + half / sigma])
    extra_s = path.s_of_u(extra_u)
    order = np.argsort(np.concatenate([nodes, extra_s]), kind="stable")
    all_s = np.concatenate([nodes, extra_s])[order]
    all_u = np.concatenate([nodes_u, extra_u])[order]
    return all_s, all_u, nodes[idx], cap


def _abs_max_over_points(x: np.ndarray, npoints: int) -> np.ndarray:
    """max over the first `npoints` points of |x| (ncell, points, naxes) -> (ncell, naxes);
    elementwise over point slices (numpy reduces a short middle axis slowly)."""
    out = np.abs(x[:, 0, :])
    for k in range(1, npoints):
        np.maximum(out, np.abs(x[:, k, :]), out=out)
    return out


def _min_over_columns(x: np.ndarray) -> np.ndarray:
    """Row minima of a (rows, few columns) array, column by column (faster than a numpy
    reduction over a short last axis)."""
    out = x[:, 0].copy()
    for k in range(1, x.shape[1]):
        np.minimum(out, x[:, k], out=out)
    return out


def feed_limit(grid: PathGrid, limits: AxisLimits, shares: BudgetShares,
               feed_cap: FeedCap | None = None) -> np.ndarray:
    """Per-cell feed limit (path units/s): min over the cell's budget points of the axis
    velocity, centripetal and geometric-jerk limits, the C1-knot cap and the feed cap."""
    nb = BUDGET_FRACTIONS.size
    # each bound falls with its |derivative|: take the largest over the budget points
    # first, then one division / root per cell and axis (the same for every layout's
    # shares: cached on the grid)
    peaks = grid._terms.get("peaks")
    if peaks is None:
        peaks = tuple(_abs_max_over_points(x, nb) for x in (grid.xs, grid.xss, grid.xsss))
        grid._terms["peaks"] = peaks
    xs, xss, xsss = peaks
    jmax = limits.jmax * grid.jerk_scale[:, None]
    with np.errstate(divide="ignore"):
        v_vel = shares.velocity * limits.vmax / xs
        v_acc = np.sqrt(shares.centripetal * limits.amax / xss)
        v_jerk = np.cbrt(shares.jerk_geometric * jmax / xsss)
    v = np.min(np.minimum(np.minimum(v_vel, v_acc), v_jerk), axis=1)
    v = np.minimum(v, grid.c1_cap)
    if feed_cap is not None:
        mid = grid.s[:, 1]
        v = np.minimum(v, feed_cap.at(mid))
    return v


def choose_segments(grid: PathGrid, vlim: np.ndarray, band_ratio: float = 1.25) -> np.ndarray:
    """Planning segments as cell index ranges: returns `starts` (nseg + 1,) with segment k
    covering cells starts[k]:starts[k+1].

    Cells are grouped into bands of the feed limit (a factor `band_ratio` wide, centred on
    an absolute feed); a segment is a maximal run of cells in one band, also cut at
    corners. A straight stroke of any number of points is one segment; a single short
    leading cell (`PathGrid.lead_cells`) belongs to the segment after it (a longer leading
    interval is cut into cells of the usual length, banded as any others: forced into the
    band after them, 70 cells of a braking start on the B-spline corners took a 6 mm
    segment's cap from the corner ahead).
    """
    # bands anchored at 1 path unit/s, so a window cuts the path where the whole job would
    band = np.floor(np.log(np.minimum(vlim, 1e300)) / np.log(band_ratio))
    if grid.lead_cells == 1 and band.size > 1:
        band[0] = band[1]
    cut = band[1:] != band[:-1]
    cut |= grid.corner_after[:-1]
    starts = np.concatenate([[0], np.nonzero(cut)[0] + 1, [grid.ncells]])
    return starts


@dataclass(frozen=True)
class SegmentBudgets:
    """Per planning segment: start s, length L, cruise cap V, path acceleration budget A,
    path jerk budget J (path units, /s, /s^2, /s^3)."""

    s0: np.ndarray
    L: np.ndarray
    V: np.ndarray
    A: np.ndarray
    J: np.ndarray


@dataclass(frozen=True)
class _BudgetTerms:
    """What `segment_budgets` and `level_accelerations` compute the same way on every
    call for one grid and one (limits, shares): the budget points flattened to columns
    (ncell, nb * naxes) of |x_s|, |x_ss|, |x_sss| and 3 |x_ss|, where |x_s| > 0 and
    |x_ss| > 0, amax and jmax tiled to the columns (with the jerk scale and the headroom)
    and the coupling share of jmax. Cached on the grid (a planner's layouts and rounds
    call the budgets 7 times a round); the same float operations as computing them in
    place."""

    xs: np.ndarray
    xss: np.ndarray
    xsss: np.ndarray
    xss3: np.ndarray
    xs_pos: np.ndarray
    xss_pos: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray
    coupling_jmax: np.ndarray


def _budget_terms(grid: PathGrid, limits: AxisLimits, shares: BudgetShares) -> _BudgetTerms:
    key = (limits.amax.tobytes(), limits.jmax.tobytes(), shares.headroom,
           shares.jerk_coupling)
    terms = grid._terms.get(key)
    if terms is None:
        nb = BUDGET_FRACTIONS.size
        ncell = grid.ncells
        xs, xss, xsss = (np.abs(x[:, :nb, :]).reshape(ncell, -1)
                         for x in (grid.xs, grid.xss, grid.xsss))
        jmax = np.tile(limits.jmax, nb) * grid.jerk_scale[:, None] * shares.headroom
        terms = _BudgetTerms(xs, xss, xsss, 3.0 * xss, xs > 0, xss > 0,
                             np.tile(limits.amax, nb) * shares.headroom, jmax,
                             shares.jerk_coupling * jmax)
        grid._terms[key] = terms
    return terms


def segment_budgets(grid: PathGrid, starts: np.ndarray, vlim: np.ndarray,
                    limits: AxisLimits, shares: BudgetShares,
                    factor: np.ndarray | None = None,
                    v_cap: np.ndarray | None = None) -> SegmentBudgets:
    """Budgets so that at every budget point of the segment, for any v <= V, |a| <= A,
    |j| <= J, each axis term stays within its limit (triangle inequality):
    A = min (amax - |x_ss| V^2) / |x_s|, also <= share * jmax / (3 |x_ss| V),
    J = min (jmax - |x_sss| V^3 - 3 |x_ss| V A) / |x_s|.
    `factor` (nseg,) <= 1 scales V, A and J down (the planner's repair); `v_cap` (nseg,)
    lowers V, which raises A and J."""
    nseg = starts.size - 1
    factor = np.ones(nseg) if factor is None else factor
    seg_of_cell = np.repeat(np.arange(nseg), np.diff(starts))
    V = np.minimum.reduceat(vlim, starts[:-1])
    if v_cap is not None:
        V = np.minimum(V, v_cap)
    V = V * factor
    # budget points flattened to columns (ncell, nb * naxes); limits tiled to match
    t = _budget_terms(grid, limits, shares)
    xs, xss, xsss = t.xs, t.xss, t.xsss
    Vc = V[seg_of_cell][:, None]
    coupling = t.xss3 * Vc  # 3 |x_ss| V
    with np.errstate(divide="ignore", invalid="ignore"):
        a_cell = np.where(t.xs_pos, (t.amax - xss * Vc**2) / xs, np.inf)
        a_cell = np.minimum(a_cell, np.where(t.xss_pos, t.coupling_jmax / coupling, np.inf))
    A = np.minimum.reduceat(_min_over_columns(a_cell), starts[:-1])
    Ac = A[seg_of_cell][:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        j_cell = np.where(t.xs_pos, (t.jmax - xsss * Vc**3 - coupling * Ac) / xs, np.inf)
    J = np.minimum.reduceat(_min_over_columns(j_cell), starts[:-1])
    s0 = grid.edges[starts[:-1]]
    L = grid.edges[starts[1:]] - s0
    return SegmentBudgets(s0, L, V, A * factor, J * factor)


def level_accelerations(grid: PathGrid, starts: np.ndarray, V: np.ndarray, J: np.ndarray,
                        limits: AxisLimits, shares: BudgetShares) -> np.ndarray:
    """Per segment the largest path acceleration A that keeps every axis term within
    its limit at every budget point for any v <= V[k], |a| <= A, |j| <= J[k]:
    A = min (amax - |x_ss| V^2) / |x_s| and (jmax - |x_sss| V^3 - |x_s| J) / (3 |x_ss| V).
    Unlike `segment_budgets` (which caps the coupling 3 |x_ss| V A at its share of jmax
    and gives the rest to J), the jerk budget J is given and the coupling takes what is
    left: below a segment's cruise cap the geometric term and the coupling per unit of
    acceleration shrink, so a feed level keeps its segment's J with a larger A."""
    nseg = starts.size - 1
    seg_of_cell = np.repeat(np.arange(nseg), np.diff(starts))
    t = _budget_terms(grid, limits, shares)
    xs, xss, xsss = t.xs, t.xss, t.xsss
    Vc = V[seg_of_cell][:, None]
    Jc = J[seg_of_cell][:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        a_cell = np.where(t.xs_pos, (t.amax - xss * Vc**2) / xs, np.inf)
        a_cell = np.minimum(a_cell, np.where(t.xss_pos, (t.jmax - xsss * Vc**3 - xs * Jc)
                                             / (t.xss3 * Vc), np.inf))
    return np.minimum.reduceat(_min_over_columns(a_cell), starts[:-1])


#: a cell is "rough" where the geometric jerk term at its feed limit, |x_sss| v^3 as a
#: fraction of jmax, changes by more than this between two of its neighbouring points
#: (a quarter cell apart): the grid points may then miss its peak between them, and the
#: planner also checks the plan's finite differences there (`verify.sampled_failing_runs`).
#: Trades compute for that check against the size of the peak the points may miss. A
#: random polyline's 1 mm blends (tests/test_heuristic_rough_cells.py) step by up to
#: 0.28-0.47 (8-28 rough cells of 2054 by layout), where a plan the grid check passed was
#: sampled at 1.035 jmax; 30 of the corpus's 64 non-long paths have rough cells (steps up
#: to 0.46, cnc-feed-mill-pocket-mixed 724 of 5520 cells), their plans all passed the
#: check unchanged, for +12 % compute on the whole-job heuristic and +4.5 % on the engine
ROUGH_JERK_STEP = 0.1
#: BUDGET_FRACTIONS + CHECK_FRACTIONS put in order along the cell (0, .25, .5, .75, 1)
_ALONG = np.array([0, 3, 1, 4, 2])


def rough_cells(grid: PathGrid, limits: AxisLimits, vlim: np.ndarray) -> np.ndarray:
    """(ncell,) True where the geometry varies too fast for the cell's five points to
    bound the geometric jerk at the feed limit `vlim` (`ROUGH_JERK_STEP`)."""
    v3 = np.where(np.isfinite(vlim), vlim, 0.0) ** 3
    jmax = limits.jmax[None, None, :] * grid.jerk_scale[:, None, None]
    share = np.abs(grid.xsss[:, _ALONG, :]) * v3[:, None, None] / jmax
    return np.max(np.abs(np.diff(share, axis=1)), axis=(1, 2)) > ROUGH_JERK_STEP

