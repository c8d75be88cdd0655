"""The paper's junctions (3.2): path acceleration 0 at every junction between planning
segments, junction feeds from kinematic compatibility. Kept as the heuristic's fallback
where the free-junction chain (`scan`) finds no motion.

1. Each junction at most the caps of both neighbours (0 at corners and at a rest end), then
   a backward and a forward pass so that every segment can make its feed change within its
   length (`scurve.reachable_feed`).
2. The first segment starts in the request's state (v, a); its end feed is found by
   bisection on Ruckig's feasibility.
3. One Ruckig S-curve (w_k, 0) -> (w_k+1, 0) per later segment.
Units: path units (mm) and seconds.
"""

from __future__ import annotations

import numpy as np

from lookahead.planning.base import PlanningError, PlanRequest
from lookahead.planning.heuristic.path_limits import PathGrid, SegmentBudgets
from lookahead.planning.heuristic.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    latest_feasible,
    reachable_feed,
)

_SLACK = 1.0 - 1e-9  # plan feed changes into a hair less than the segment length


def junction_caps(request: PlanRequest, grid: PathGrid, starts: np.ndarray,
                  b: SegmentBudgets) -> np.ndarray:
    """(nseg + 1,) feed caps at the junctions: the start feed, the lower V of the two
    neighbours (0 at a corner), the end feed."""
    nseg = b.L.size
    w = np.empty(nseg + 1)
    w[0] = request.start.v
    w[1:-1] = np.minimum(b.V[:-1], b.V[1:])
    w[1:-1][grid.corner_after[starts[1:-1] - 1]] = 0.0
    w[-1] = min(request.v_end, b.V[-1])
    return w


def junction_feeds(request: PlanRequest, grid: PathGrid, starts: np.ndarray,
                   b: SegmentBudgets, slack: float = _SLACK) -> np.ndarray:
    """Upper bounds of the junction feeds (nseg + 1,), junction 0 being the start; each
    feed change is planned into `slack` times the segment length."""
    w = backward_pass(junction_caps(request, grid, starts, b), b, slack)
    forward_pass(w, b, slack)
    return w


def backward_pass(w: np.ndarray, b: SegmentBudgets, slack: float = _SLACK) -> np.ndarray:
    """Lower junction feeds 1.. in place (and return w) to what each later segment can
    slow down from to its end's feed (a scalar loop: each junction depends on the next;
    on Python floats, 3x faster than on numpy scalars, the same operations)."""
    v, L, A, J = (x.tolist() for x in (w, b.L, b.A, b.J))
    for k in range(len(L) - 1, 0, -1):
        v[k] = min(v[k], reachable_feed(v[k + 1], L[k] * slack, A[k], J[k]))
    w[:] = v
    return w


def forward_pass(w: np.ndarray, b: SegmentBudgets, slack: float = _SLACK) -> None:
    """Lower junction feeds 2.. in place to what each segment can reach from the last
    (on Python floats, as `backward_pass`)."""
    v, L, A, J = (x.tolist() for x in (w, b.L, b.A, b.J))
    for k in range(1, len(L)):
        v[k + 1] = min(v[k + 1], reachable_feed(v[k], L[k] * slack, A[k], J[k]))
    w[:] = v


def first_segment(solver: SCurveSolver, request: PlanRequest, b: SegmentBudgets,
                  w1_hi: float, margin: float) -> tuple[Phases, float]:
    """S-curve from the start state to the highest feasible end feed <= w1_hi, by
    bisection on Ruckig's feasibility (raises SegmentInfeasibleError if none is)."""
    st = request.start
    args = (float(b.s0[0]), float(b.L[0]), st.v, st.a)
    V, A = first_caps(st.v, st.a, float(b.V[0]), float(b.A[0]), margin)
    caps = (V, A, float(b.J[0]))

    def attempt(w1: float) -> Phases | None:
        try:
            return solver.segment(*args, w1, *caps)
        except SegmentInfeasibleError:
            return None

    best = attempt(w1_hi)
    if best is not None:
        return best, w1_hi
    # feasible end feeds form an interval; find one, then bisect upwards towards w1_hi
    lo = None
    for w in np.linspace(0.0, w1_hi, 9)[:-1]:
        best = attempt(float(w))
        if best is not None:
            lo = float(w)
    if lo is None:
        raise SegmentInfeasibleError("no end feed reachable from the start state")
    return latest_feasible(attempt, lo, min(w1_hi, lo + w1_hi / 8.0), 30,
                           1e-6 * max(w1_hi, 1e-12), attempt(lo))


def first_caps(v0: float, a0: float, V: float, A: float, margin: float) -> tuple[float, float]:
    """The first segment's V and A, stretched to admit the start state: a start state from
    a plan of the same path may sit a hair outside this window's budgets (other cells,
    other sample points); within the margin to the true limits the budgets stretch to
    include it instead of braking."""
    stretch = 1.0 / margin
    V = max(V, v0) if v0 <= V * stretch else V
    A = max(A, abs(a0)) if abs(a0) <= A * stretch else A
    return V, A


def later_segment(solver: SCurveSolver, k: int, b: SegmentBudgets, w: np.ndarray) -> Phases:
    """S-curve (w[k], 0) -> (w[k+1], 0); if rounding defeats Ruckig at the exact
    compatibility limit, lower the end feed slightly (written back into w)."""
    for attempt in range(8):
        try:
            return solver.segment(float(b.s0[k]), float(b.L[k]), float(w[k]), 0.0,
                                  float(w[k + 1]), float(b.V[k]), float(b.A[k]),
                                  float(b.J[k]))
        except SegmentInfeasibleError:
            w[k + 1] *= 1.0 - 10.0 ** (attempt - 7)
    raise PlanningError(f"segment {k} at s={b.s0[k]:.6g}: no S-curve from feed {w[k]:.6g}")


def zero_junction_parts(solver: SCurveSolver, request: PlanRequest, grid: PathGrid,
                        starts: np.ndarray, b: SegmentBudgets, margin: float
                        ) -> list[Phases]:
    """The phases per segment (raises SegmentInfeasibleError if the start state cannot
    reach a valid end state within the first segment)."""
    # the first segment needs only junction 1, which the forward pass does not change:
    # it runs once the first segment is found (the leading-segment merges of
    # `HeuristicPlanner._profile_phases` call this per merge; from braking butterfly
    # replans ~45 times a round, where the forward pass was a third of the replan)
    w = backward_pass(junction_caps(request, grid, starts, b), b)
    first, w1 = first_segment(solver, request, b, float(w[1]), margin)
    forward_pass(w, b)
    if w1 < w[1]:
        w[1] = w1
        forward_pass(w, b)
    return [first] + [later_segment(solver, k, b, w) for k in range(1, b.L.size)]
