"""The s-grid of the feed LP: uniform spacing, graded towards the points where the feed is 0.

Near a point of rest the jerk-limited feed grows like q ~ s^(4/3) (s = J t^3 / 6), which a
uniform grid resolves badly; intervals there start at `h / grade_ratio` and grow
geometrically to h.
"""

from __future__ import annotations

import numpy as np


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
