"""The s-grid of the feed LP: uniform spacing, graded towards the points where the feed is 0.

Near a point of rest the jerk-limited feed grows like q ~ s^(4/3) (s = J t^3 / 6), which a
uniform grid resolves badly; intervals there start at `h / grade_ratio` and grow
geometrically to h.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from lookahead.planning.base import FeedCap


def graded_span(length: float, h: float, grade_start: bool, grade_end: bool,
                first: float, growth: float = 1.25) -> np.ndarray:
    """Offsets 0 .. length with spacing ~h, graded from `first` at the flagged ends."""
    n = max(int(np.ceil(length / h)), 2)
    ramp = []
    step = first
    while step < h and sum(ramp) + step < 0.25 * length:
        ramp.append(step)
        step *= growth
    ramp = np.array(ramp)
    head = ramp if grade_start else np.empty(0)
    tail = ramp[::-1] if grade_end else np.empty(0)
    middle = length - head.sum() - tail.sum()
    n = max(int(np.ceil(middle / h)), 2)
    steps = np.concatenate([head, np.full(n, middle / n), tail])
    offsets = np.concatenate([[0.0], np.cumsum(steps)])
    offsets[-1] = length
    return offsets


def build_grid(s0: float, s1: float, h: float, rest_start: bool, rest_end: bool,
               stops: np.ndarray, grade_ratio: float = 25.0) -> tuple[np.ndarray, np.ndarray]:
    """Nodes from s0 to s1 (path units) and the indices of the nodes at `stops` (rest points
    strictly inside), every sub-span graded at its rest ends."""
    stops = np.sort(np.asarray(stops, dtype=float))
    stops = stops[(stops > s0 + 1e-9) & (stops < s1 - 1e-9)]
    edges = np.concatenate([[s0], stops, [s1]])
    pieces, stop_idx, count = [], [], 0
    for j in range(edges.size - 1):
        length = edges[j + 1] - edges[j]
        span_h = min(h, length / 8.0)
        offs = graded_span(length, span_h, rest_start or j > 0,
                           rest_end or j < edges.size - 2, span_h / grade_ratio)
        nodes = edges[j] + offs
        if j > 0:
            nodes = nodes[1:]
            stop_idx.append(count - 1)
        pieces.append(nodes)
        count += nodes.size
    return np.concatenate(pieces), np.array(stop_idx, dtype=int)


def extend_grid(head: np.ndarray, s1: float, h: float, rest_end: bool, stops: np.ndarray,
                head_stops: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A replan's grid: the reused nodes `head` (with rest-point indices `head_stops`),
    then fresh nodes from head[-1] to s1 (path units) as `build_grid` places them."""
    tail, tail_stops = build_grid(float(head[-1]), s1, h, False, rest_end, stops)
    nodes = np.concatenate([head, tail[1:]])
    return nodes, np.concatenate([head_stops, tail_stops + head.size - 1]).astype(int)


#: wanted node spacing as a fraction of the local feature length (1 / curvature in the
#: path metric, and 1 / sqrt(|x_sss|)): trades LP size for resolving sharp bends.
#: Measured through the engine on issue 13's paths (fallbacks, Fourier / butterfly):
#: 0.25 with grading 1.3: 6 / 6; 0.5 with 1.2: 0 / -; 1.0 with 1.15: 0 / 5, the fastest.
#: The presets' bends (radius >= 100 mm) get no extra nodes.
FEATURE_STEP = 1.0
#: the refined spacing is at least this fraction of the nominal one (true cusps are
#: corners, `Path.corners_s`, where the grid already comes to rest)
MIN_STEP_FRACTION = 1.0 / 64.0


#: a tangent turn (path metric, rad) between neighbouring feature samples above
#: max(HIDDEN_TURN, HIDDEN_FACTOR x the turn their curvature explains) hides a bend
#: shorter than their spacing, which is then sampled HIDDEN_SAMPLES times finer (unless a
#: rest node lies there: `near_reversals`). A bend matters to the grid when its curvature
#: exceeds 1 / h, i.e. a turn > 1/4 rad over one h/4 spacing; 0.05 rad keeps a margin below
#: that. The factor trades plan speed for grid size: on the whole corpus (short of its
#: 100k-point paths) turn / explained is 1.0 on resolved bends and at most 5.1 elsewhere
#: (c-corners-bspline-2d, w-hel-R100-a45-dwell-2mm: 4.5); at 4 those two got finer grids
#: and c-corners planned 1.7 % slower in 8x the compute; at 8 no corpus plan changes. The
#: 100k-line winding program's G-code corner blends (0.64 mm, radius 0.15 mm between
#: samples 1.5 mm apart: 1.2 rad against ~0 explained) qualify; every repair of its
#: whole-job LP failed at one of them before.
HIDDEN_TURN = 0.05
HIDDEN_FACTOR = 8.0
HIDDEN_SAMPLES = 32


def feature_samples(path, lo: float, hi: float, spacing: float,
                    stops: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Arc lengths lo..hi (path units, increasing) on which the grid judges the path's
    bends, and the path's derivatives there (`Path.eval_s` order 3): `spacing` apart, and
    HIDDEN_SAMPLES times finer between two samples whose tangents turn by more than their
    curvature explains (a bend shorter than `spacing` between them) unless a rest node
    (`stops`, path units: a corner or near-reversal, graded already) lies between them."""
    n = int(np.ceil((hi - lo) / spacing)) + 1
    s = np.linspace(lo, hi, n)
    d = path.eval_s(s, 3)
    if n < 2:
        return s, d
    scale = np.asarray(path.path_scale, dtype=float)
    t = d[1] * scale
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    turn = np.arccos(np.clip(np.sum(t[:-1] * t[1:], axis=1), -1.0, 1.0))
    k = np.linalg.norm(d[2] * scale, axis=1)
    explained = HIDDEN_FACTOR * np.maximum(k[:-1], k[1:]) * np.diff(s)
    hidden = turn > np.maximum(HIDDEN_TURN, explained)
    stops = np.empty(0) if stops is None else np.asarray(stops, dtype=float)
    at_rest = np.searchsorted(s, stops, side="right") - 1
    for off in (-1, 0, 1):  # a near-reversal's rest node may lie one interval off
        i = at_rest + off
        hidden[i[(i >= 0) & (i < n - 1)]] = False
    hidden = np.nonzero(hidden)[0]
    if hidden.size == 0:
        return s, d
    frac = np.arange(1, HIDDEN_SAMPLES) / HIDDEN_SAMPLES
    extra = (s[hidden, None] + np.diff(s)[hidden, None] * frac).ravel()
    s_all = np.concatenate([s, extra])
    order = np.argsort(s_all, kind="stable")
    d_extra = path.eval_s(extra, 3)
    return s_all[order], np.concatenate([d, d_extra], axis=1)[:, order]


def feature_steps(s: np.ndarray, d2: np.ndarray, d3: np.ndarray, path_scale: np.ndarray,
                  h: float) -> np.ndarray:
    """The node spacing wanted at arc lengths s (path units) from the path's s-derivatives
    x_ss, x_sss (each (n, naxes), axis units) scaled to the path metric by `path_scale`:
    min(h, FEATURE_STEP / curvature, FEATURE_STEP / sqrt(|x_sss|)), at least
    MIN_STEP_FRACTION h, taken as the smallest over each sample and its neighbours."""
    k2 = np.max(np.abs(d2 * path_scale), axis=1)
    k3 = np.sqrt(np.max(np.abs(d3 * path_scale), axis=1))
    with np.errstate(divide="ignore"):
        step = np.minimum(FEATURE_STEP / k2, FEATURE_STEP / k3)
    step = np.clip(step, MIN_STEP_FRACTION * h, h)
    step[1:] = np.minimum(step[1:], step[:-1])
    step[:-1] = np.minimum(step[:-1], step[1:])
    return step


def limit_curve_feed(d2: np.ndarray, d3: np.ndarray, amax: np.ndarray,
                     jmax: np.ndarray) -> np.ndarray:
    """The feed (path units / s) at which one axis alone reaches its acceleration or jerk
    limit from the geometry at constant feed, per sample: min over axes of
    sqrt(amax_k / |x_ss,k|) and cbrt(jmax_k / |x_sss,k|) (d2, d3: x_ss, x_sss, each
    (n, naxes), axis units per path unit^2, ^3). Not a bound on the plan (the path
    acceleration and jerk terms can cancel the geometric ones), an estimate of where the
    plan must be slow because the path bends. The velocity limits are left out: at its
    velocity cap the feed is steady, with nothing for the reconstruction to follow
    (with them the tube's windows had 1.4x the nodes for the same plan)."""
    with np.errstate(divide="ignore"):
        v = np.minimum(np.sqrt(amax / np.abs(d2)), np.cbrt(jmax / np.abs(d3)))
    return np.min(v, axis=1)


def limit_curve_steps(feed: np.ndarray, h: float, v_top: float) -> np.ndarray:
    """The node spacing wanted where the limit-curve feed is `feed` (`limit_curve_feed`,
    path units / s): h feed / v_top, so that an interval takes no longer at that feed
    than an interval h long at v_top (the feed the nominal spacing h is made for,
    `planner.default_grid_step`), clipped to [MIN_STEP_FRACTION h, h] and taken as the
    smallest over each sample and its neighbours.

    Why (issue 13): the quintic reconstruction between two nodes follows the LP's path
    jerk only to within the change the jerk-change rows allow per node (a fixed fraction
    of jmax), so nodes far apart in time hold the jerk nearly constant over long times:
    on a uniform grid the polar dome's pole (feed ~100 mm/s, nodes 2.8 mm = 30-50 ms
    apart) planned 2.14 s, and cam-style's locks (x_sss changes within 1.5 mm at
    690 mm/s, no refinement by `feature_steps`) 7.94 s after 6 failed repairs and a
    retry; with these steps 1.79 s and 7.52 s (whole job, fast corpus). No new constant:
    the time per interval is the nominal grid's."""
    step = np.clip(h * feed / v_top, MIN_STEP_FRACTION * h, h)
    step[1:] = np.minimum(step[1:], step[:-1])
    step[:-1] = np.minimum(step[:-1], step[1:])
    return step


def break_steps(feed_cap: FeedCap, s_feat: np.ndarray, step: np.ndarray, h: float, v_top: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """The wanted spacing `step` (at arc lengths s_feat, path units) with a sample at each
    change of `feed_cap` inside [s_feat[0], s_feat[-1]], wanting there the
    spacing `limit_curve_steps` gives the lower of the two caps; `refine_grid` grades it
    back to the spacing around.

    Why: where the feed lands on a low cap or leaves it, the reconstruction between
    nodes far apart in time overshoots the jerk rows (a line capped 80 -> 5 -> 80 mm/s:
    1.2-1.36 J in the intervals beside the breaks, 4 repair rounds that left 1.18 J)."""
    b = feed_cap.changes()
    b = b[(b > s_feat[0]) & (b < s_feat[-1])]
    if b.size == 0:
        return s_feat, step
    low = np.minimum(feed_cap.at(b), feed_cap.at(np.nextafter(b, -np.inf)))
    return point_steps(s_feat, step, b, np.clip(h * low / v_top, MIN_STEP_FRACTION * h, h))


def point_steps(s_feat: np.ndarray, step: np.ndarray, points: np.ndarray, want: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The wanted spacing `step` (at arc lengths s_feat) with a sample at each of `points`
    (inside the span) wanting no more than `want` there (path units)."""
    s_all = np.concatenate([s_feat, points])
    order = np.argsort(s_all, kind="stable")
    at_points = np.interp(points, s_feat, step)
    return s_all[order], np.concatenate([step, np.minimum(want, at_points)])[order]


def refine_grid(nodes: np.ndarray, stop_idx: np.ndarray, s_feat: np.ndarray,
                step: np.ndarray, first: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """More nodes wherever the wanted spacing `step` (given at arc lengths s_feat,
    increasing, path units) is below an interval's length, from node `first` on; returns
    the nodes and the shifted indices of the rest nodes `stop_idx`. Nodes before `first`
    (a seam's reused nodes) and all existing nodes are kept.

    The wanted spacing is first graded (it may grow by at most GRADE_LIMIT - 1 of itself
    per unit of its own length, both ways), then each interval gets ceil(integral of
    ds / step) parts placed at equal steps of that integral, so that neighbouring new
    intervals differ by about GRADE_LIMIT at most. Hand-written: a density-based node
    placement (two sweeps and an inverse interpolation), which no library offers for a
    grid with fixed nodes."""
    if nodes.size < 2 or s_feat.size < 2:
        return nodes, stop_idx
    w = graded_steps(s_feat, step)
    density = 1.0 / w
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1])
                                           * np.diff(s_feat))])
    F = np.interp(nodes, s_feat, cum)
    need = np.diff(F)
    parts = np.maximum(np.ceil(need - 1e-6).astype(int), 1)
    parts[:first] = 1
    parts[np.diff(nodes) <= 0.0] = 1
    if np.all(parts == 1):
        return nodes, stop_idx
    pieces = [nodes[:1]]
    for j in range(nodes.size - 1):
        k = parts[j]
        if k > 1:
            targets = F[j] + need[j] * np.arange(1, k) / k
            pieces.append(np.interp(targets, cum, s_feat))
        pieces.append(nodes[j + 1:j + 2])
    out = np.concatenate(pieces)
    offset = np.concatenate([[0], np.cumsum(parts - 1)])
    return out, (stop_idx + offset[stop_idx]).astype(int)


#: largest growth of the refined spacing per unit of its own length (a 2x jump between
#: neighbouring intervals left a node at q ~ 0 on the B-spline composite of
#: test_lp_short_paths; see FEATURE_STEP for the measurements)
GRADE_LIMIT = 1.15


def graded_steps(s: np.ndarray, step: np.ndarray) -> np.ndarray:
    """`step` (at increasing arc lengths s) lowered so that it grows by at most
    (GRADE_LIMIT - 1) |ds| from any sample to the next, both ways (two running minima)."""
    slope = GRADE_LIMIT - 1.0
    # forward: min over j <= i of step_j + slope (s_i - s_j); backward likewise
    fwd = slope * s + np.minimum.accumulate(step - slope * s)
    bwd = -slope * s + np.minimum.accumulate((step + slope * s)[::-1])[::-1]
    return np.minimum(fwd, bwd)


#: a turn of the tangent (path metric) by more than this between feature samples marks a
#: hidden near-reversal (cos of 120 deg)
REVERSAL_COS = -0.5
#: points per bracket in the search for a near-reversal's sharpest point, at least two
#: rounds and then more (up to REVERSAL_ROUNDS) while the bracket is wider than
#: REVERSAL_PRECISION x the radius of curvature there: two rounds put the rest node of a
#: fuzzed cubic walk's 179 deg turn (radius 3.8e-5, grid step 2.9) 1.4e-4 off its sharpest
#: point, which the plan passed at 3.5x jmax, every repair stuck (`bench/fuzz_paths.py
#: --method lp`, case 2); on the corpus 4 of its 6 such points move, by 5e-6 .. 8e-5
REVERSAL_SEARCH = 65
REVERSAL_ROUNDS = 8
REVERSAL_PRECISION = 0.1


def near_reversals(path, h: float, samples_per_step: int = 4) -> np.ndarray:
    """Arc lengths (path units) of near-reversals the grid cannot resolve: the tangent
    turns by more than 120 deg over one or two samples h / samples_per_step apart, and the
    sharpest point found in between has a radius of curvature below MIN_STEP_FRACTION h.

    Such a point (c-corners-bspline-2d: a 177 deg turn within 0.45 mm, radius 0.014 mm;
    c-cycloid-near-cusp) is smooth, so `Path.corners_s` does not list it, but the feed
    must nearly stop there anyway (x_sss v^3 <= J); the planner makes it a rest node.
    Samples h / 4 apart do not see the curvature peak itself (it is ~1e-3 of their
    spacing wide), only the turn of the tangent across it."""
    n = int(np.ceil(path.length / h * samples_per_step)) + 1
    if n < 3:
        return np.empty(0)
    s = np.linspace(0.0, path.length, n)
    scale = np.asarray(path.path_scale, dtype=float)
    t = path.eval_s(s, 1)[1] * scale
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    # over one and two sample steps: a sample on the sharp point itself splits the turn
    brackets = [(int(i), int(i) + lag) for lag in (1, 2)
                for i in np.nonzero(np.sum(t[:-lag] * t[lag:], axis=1) < REVERSAL_COS)[0]]
    found: list[float] = []
    for i, i_end in brackets:
        lo, hi = s[i], s[i_end]
        if any(lo <= f <= hi for f in found):
            continue
        for rounds in range(1, REVERSAL_ROUNDS + 1):
            x = np.linspace(lo, hi, REVERSAL_SEARCH)
            k = np.max(np.abs(path.eval_s(x, 2)[2] * scale), axis=1)
            j = int(np.argmax(k))
            lo, hi = x[max(j - 1, 0)], x[min(j + 1, x.size - 1)]
            if rounds >= 2 and (hi - lo) * k[j] < REVERSAL_PRECISION:
                break
        if k[j] * MIN_STEP_FRACTION * h > 1.0:
            found.append(float(x[j]))
    return np.array(found)


def split_near(nodes: np.ndarray, stop_idx: np.ndarray, places: np.ndarray, parts: int = 4,
               reach: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The nodes with every interval within `reach` intervals of each arc length in
    `places` (path units) split into `parts` equal ones, and the shifted rest-node
    indices. For a plan whose sampled check kept failing there after its repairs: a
    violation between the nodes that tightening the nodal rows does not remove is a
    bend the grid does not resolve (the butterfly NURBS: x_sss changes sign within one
    interval, the reconstructed jerk stayed at 1.1-1.2 J with the jerk factors at 0.4)."""
    places = np.asarray(places, dtype=float)
    if nodes.size < 2 or places.size == 0:
        return nodes, stop_idx
    m = nodes.size - 1
    hit = np.clip(np.searchsorted(nodes, places) - 1, 0, m - 1)
    mark = np.zeros(m, dtype=bool)
    for off in range(-reach, reach + 1):
        mark[np.clip(hit + off, 0, m - 1)] = True
    k = np.where(mark, parts, 1)
    pieces = [nodes[:1]]
    for j in range(m):
        if k[j] > 1:
            pieces.append(nodes[j] + (nodes[j + 1] - nodes[j]) * np.arange(1, k[j]) / k[j])
        pieces.append(nodes[j + 1:j + 2])
    offset = np.concatenate([[0], np.cumsum(k - 1)])
    return np.concatenate(pieces), (stop_idx + offset[stop_idx]).astype(int)


#: a feed-cap break closer than this fraction of the shorter interval beside a node moves
#: that node onto it (further: a node is inserted). Keeps the intervals beside a moved
#: node at >= 3/4 of what the grid chose, and no interval shorter than a quarter of its
#: neighbour from an insertion
BREAK_SNAP = 0.25


def with_breaks(nodes: np.ndarray, stop_idx: np.ndarray, breaks: np.ndarray,
                first: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The nodes with a node on every feed-cap break (path units) strictly after node
    `first` and before the last node, and the shifted rest-node indices: the nearest
    node moves onto a break within BREAK_SNAP of its interval, otherwise a node is
    inserted; rest nodes and nodes up to `first` (a seam's reused ones) never move, and
    a break beside a rest node is left to `FeedCap.at_nodes` (the rest node's neighbours
    take the smaller cap).

    Why: the LP caps the feed at its nodes only, and a node-to-node interval across a
    break carries the higher cap's feed into the lower one (cnc-feed-mill-pocket-mixed:
    18 % over F300 after an F1200 pass, velocity repairs in every round of the whole-job
    LP until it gave up)."""
    breaks = np.asarray(breaks, dtype=float)
    if nodes.size < 2 or breaks.size == 0:
        return nodes, stop_idx
    s = nodes.copy()
    fixed = np.zeros(s.size, dtype=bool)
    fixed[:first + 1] = True
    fixed[-1] = True
    fixed[stop_idx] = True
    inside = breaks[(breaks > s[first]) & (breaks < s[-1])]
    extra = []
    for b in inside:
        j = int(np.searchsorted(s, b))  # s[j-1] < b <= s[j]
        if s[j] == b:
            continue
        k = j if s[j] - b < b - s[j - 1] else j - 1  # the nearest node
        gap = min(s[k] - s[k - 1], s[k + 1] - s[k]) if 0 < k < s.size - 1 else 0.0
        if not fixed[k] and abs(s[k] - b) < BREAK_SNAP * gap:
            s[k] = b
            fixed[k] = True
        elif not (fixed[k] and k in stop_idx):
            extra.append(b)
    if not extra:
        return s, stop_idx
    extra_arr = np.array(extra)
    out = np.sort(np.concatenate([s, extra_arr]))
    shift = np.searchsorted(extra_arr, s[stop_idx])
    return out, (stop_idx + shift).astype(int)
