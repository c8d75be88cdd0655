"""The LP feed planner (the paper's 3.3, Fan et al.): q = (ds/dt)^2 on an s-grid.

Pass 0 solves the velocity + acceleration LP; later passes add the jerk rows linearized
at the last solution (tangent of J / sqrt(q), conservative at the nodes) and stop when
the travel time no longer improves. The grid solution becomes a C2 quintic profile
(`lp.profile`), whose continuous axis velocity, acceleration and jerk are checked every
dt/2 (`sampled_check.analytic_ratios`, a bound on the checker's finite differences);
where it breaks a limit (between nodes the jerk can overshoot), the rows of the nearby
nodes are tightened and one jerk pass is solved again (the repair loop; after its first
round only on zones around the excesses, `lp.local_repair`).

Feasibility (issue 13): q = 0 satisfies every velocity, acceleration, jerk and jerk-change
row, so from rest to rest every LP here is feasible; what can make it infeasible is what
fixes q away from 0: a moving start (its slope row and first nodes), a seam's fixed nodes,
a moving end, and lower bounds. Lower bounds are never imposed: the stall floors of
`_unstall` are tried and dropped when infeasible. The grid is refined where the path bends
sharply (`refine`), so the nodal rows see a near-cusp; a near-reversal too sharp for
any grid (`lp.grid.near_reversals`) becomes a rest node, like a corner. A repair loop far
from converging gives up early (HOPELESS_RATIO); one that keeps making progress at new
places (a long grid) gets more rounds (REPAIRS_PER_BUDGET).

Between two rest points (corners, near-reversals, the job's start and end) the plan
depends on nothing outside: such stretches of at most SPLICE_MAX_NODES nodes are planned by
the transient planner too, whose plan replaces the LP's where it is faster and passes the
same check (`rest_splice`, `lp.rest_stretches`: the LP's grid loses ~25 % on short
jerk-dominated moves between stops, at any grid step).

A feed cap (segment feeds, override) changes value at segment ends: each change is a
node (`lp.grid.with_breaks`), the nodes beside it are as close in time at the lower cap
as elsewhere at the top feed (`lp.grid.break_steps`), and every node keeps the smaller
cap of the two intervals beside it (`FeedCap.at_nodes`), so no interval carries one
cap's feed into the other's.

A moving start (not on the last plan) is handed over by another plan, often one at the
full limits (the heuristic's, after a fallback), while the LP's rows are the limits times
margins; built in, always: the velocity caps leave room for the braking from the start
state (`_brake_room`: from v_cap with a = 0 no bounded jerk reaches 0.995 v_cap within one
node, the cascade of issue 13; where that braking cannot come to rest within the window,
the room is capped by the way into the end at its own tangents, `_rest_caps`), a braking
start's envelope releases at least as fast as
a0^2 / v0 (else it forced a stall), the first node has an exact jerk row
(`rows.start_jerk_rows`), and a start above the limits (an override) is judged against
its own excess while a braking could not yet have removed it (`_start_allowance`; an
acceleration above the limits, over the first grid interval: `_start_acc_allowance`); a
braking start whose acceleration would reach 0 within one grid step (the braking into a
plan's end at low feed) is first released in closed form (`lp.release`). If the
LP is still infeasible, it is relaxed in this order: (1) the start zone (two braking
distances, `_start_zone`) gets the limits themselves (factors 1), and where that plans,
the zone's own factors are solved once more with the jerk rows linearized at the relaxed
solution (`_remargin`), which is the plan when feasible; (2) its rows become elastic
(`lp.elastic`: slacks at a dominating cost, feasible whatever the start, exact where the
hard LP is feasible). Step (1) is skipped when a repair's tightening made the
LP infeasible: it would undo that repair, and the same excess came back every round;
such a repair is first tried at fractions of its tightening within the start zone
(REPAIR_BACKOFF), as the elastic rows take a repair near the start as slack, and the
excess grows.
The sampled check judges every result as always. A moving start or seam that still
fails goes, in this order, to: a smaller kept head of the last plan, a cold plan from
the start state, the start's transient planned by the heuristic up to its first
zero-acceleration state from which the LP plans (`lp.handover`; a transient that only
brakes to the window's end is that stop), then the caller (the engine's stop planner,
counted as a fallback).

Two more causes of failed or slow plans: a jerk pass that leaves a node far below its
linearization point is re-linearized (RELINEARIZE_RATIO: the tangent pins it near 0,
which made a 6.7 s window take 18 s), and at a C1 path's knots the checker's third
difference adds KNOT_FD_SHARE |jump of x_ss| v^2 / dt to the jerk, which the jerk rows
and the check now include (`lp.knots`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import (
    FeedCap,
    FeedProfile,
    PathState,
    Planner,
    PlanningError,
    PlanRequest,
    PlanResult,
)
from lookahead.planning.lp.elastic import elastic_lp
from lookahead.planning.lp.envelope import (
    braking_distance,
    braking_q,
    envelope_limits,
    local_rest_q,
    lowered_rest_envelope,
    path_limits,
    reachable_q,
    rest_envelope,
    tangent_limits,
)
from lookahead.planning.lp.grid import (
    break_steps,
    build_grid,
    extend_grid,
    feature_samples,
    feature_steps,
    limit_curve_feed,
    limit_curve_steps,
    near_reversals,
    refine_grid,
    split_near,
    with_breaks,
)
from lookahead.planning.lp.handover import plan_handed_over
from lookahead.planning.lp.knots import c1_knot_caps, knot_fd_ratio, knot_jumps, knot_steps
from lookahead.planning.lp.local_repair import (
    held_rows,
    repair_zone,
    zone_rows,
)
from lookahead.planning.lp.profile import (
    grid_time,
    node_accelerations,
    profile_from_grid,
)
from lookahead.planning.lp.release import start_release
from lookahead.planning.lp.rest_stretches import (
    Splice,
    find_splice,
    interior_worst,
    node_times,
    rest_spans,
    splice_at,
    swap_spans,
)
from lookahead.planning.lp.rows import (
    GridGeometry,
    Rows,
    Tightening,
    acceleration_rows,
    end_acceleration_rows,
    end_slope_row,
    free_rows,
    jerk_change_rows,
    jerk_rows,
    start_jerk_rows,
    start_slope_row,
    velocity_caps,
)
from lookahead.planning.lp.seam import (
    FIXED_NODES,
    REST,
    LastPlan,
    Seam,
    find_seam,
    join_last,
)
from lookahead.planning.lp.solve import ScaledLP, make_backend
from lookahead.planning.place import PlacedPlanningError
from lookahead.planning.profile_ops import concatenate, slice_profile
from lookahead.planning.sampled_check import SampledRatios, analytic_ratios


@dataclass
class GridPlan:
    """An LP solution on the grid and the history of its passes."""

    s: np.ndarray
    q: np.ndarray
    time_s: float
    pass_times: list[float] = field(default_factory=list)
    solver_ms: list[float] = field(default_factory=list)
    statuses: list[str] = field(default_factory=list)


#: a failed plan from scratch is tried on finer grids up to this many intervals
MAX_REFINED_NODES = 256
#: a plan from scratch whose repairs did not converge is tried once more with the jerk
#: margin times this (measured: a butterfly window stuck at +0.4 % jerk after 8 repairs
#: planned with 0.85 -> 0.75; scaling the repaired factors instead made it +1.6 %)
RETRY_JERK_MARGIN = 0.88
#: a repair loop still above HOPELESS_RATIO x a limit after HOPELESS_AFTER repairs gives
#: up (the next fallback in `plan` / `_plan_cold` follows): measured on the fast corpus,
#: every loop that converged stayed below 4.5 x (c-rand6-scales, c-fourier-xc) while the
#: ones that never converged were at 11-2300 x (c-cycloid-near-cusp, c-corners-bspline-2d)
#: and spent up to 9 s in their remaining repairs; same plans, same fallbacks
HOPELESS_RATIO = 10.0
HOPELESS_AFTER = 2
#: a repair round of a plan from scratch whose worst excess lies within STUCK_REACH
#: nodes of the worst places of STUCK_REPEATS earlier rounds is stuck: tightening the
#: nodal rows there does not remove it (a bend the grid does not resolve, `split_near`),
#: and the plan gives up at once for the split grid (`_plan_cold`). Measured on the fast
#: corpus: n-butterfly's repairs hit s = 97.49 in 6 of 9 rounds, c-fourier-xc's 11585.5
#: and 11309.4 in 4 and 5, each plan ending in a failure after 8 repairs
STUCK_REPEATS = 2
STUCK_REACH = 2
#: a repair round that made progress (its check's worst excess lies at a new place,
#: beyond STUCK_REACH nodes of every earlier round's, and is the smallest so far) does
#: not count against `max_repairs`, up to this many times max_repairs rounds in all: a
#: long grid has many independent places, and each round's re-solve (the jerk rows
#: re-linearized at its solution) moves small excesses to others. Measured:
#: cnc-feed-mill-pocket-mixed's whole-job LP (4341 nodes) converged after 10 rounds,
#: it gave up after 8 and failed; without the "smallest so far" condition the fiberpath
#: programs' whole-job LPs (15k nodes, excesses growing 1.15 -> 2.6 J at ever new
#: places) spent all 32 rounds before the retry that plans them: 4x the compute.
REPAIRS_PER_BUDGET = 4
#: samples per nominal grid step on which `LPPlanner.refine` judges the path's bends
FEATURE_SAMPLES = 4
#: `_unstall`'s time-gradient reference: q floored at this fraction of its upper bound
#: (smaller values a stalled node more; 1e-3 lifted every stall of the issue-13 Fourier
#: and butterfly paths, which 1e-9 .. q_hi weights left at 0)
STALL_REF = 1e-3
#: how far the feed may exceed a segment's feed cap between the LP's nodes before a
#: repair (fraction of the cap): without it, overshoots of 1e-5 took repair rounds from
#: the jerk, and the whole-job LP failed on 4 of the 5 G-code paths of the corpus
FEED_CAP_TOL = 0.005
#: jerk passes that may re-linearize a stalled first solution (`solve_grid`): the
#: 1500-point butterfly's first window stalled two adjacent nodes 0.014 mm apart on the
#: limit-curve grid ("the jerk LP has no solution", a fallback since a31aa5c)
STALL_PASSES = 2
#: floor attempts in `_unstall` (each one 4x lower after an infeasible one)
STALL_FLOOR_TRIES = 4

#: jerk passes of a seam plan's first solve (`LPPlanner.seam_passes`; max_passes if more):
#: its fresh nodes are linearized at their upper bounds, far above the feed of a turnaround
#: just after the last plan's window end, and one pass left the replan ~20 % slower there
#: than a plan without that window end (cam-fp-hel70: the windowed job 1.2 % over the whole
#: job; tests/test_lp_seam_passes.py). Trades replan compute for winding time. Engine-lp on
#: the 64 non-long corpus paths (bench/results/corpus_seam_passes.json): windowed / whole
#: job worst 1.0119 -> 1.0063, 8 paths faster (up to -1.24 %, cam-fp-layers), 2 slower
#: (+1.10 % cam-style-R100, still 1.002x its whole job; +0.12 %); simplex iterations on the
#: 16 hard paths 1.05x (cam-fp-layers 1.39x; bench/results/lp_work_seam_passes.json). 2
#: passes: hel70 44.10 s, 3: 43.83 s, the whole job 43.77 s. Not for OSQP: its engine on
#: the fast subset took 1.52x the compute (1.17x with the mill) for winding within -0.20 ..
#: +1.06 % (bench/results/corpus_osqp_seam_passes{,_before}.json, side by side)
SEAM_PASSES = 3
#: repair rounds after the first (`LPPlanner.local_repair`, `lp.local_repair`): re-solve the
#: nodes within this many of an interval with a sampled excess, the rest held at the last
#: plan; an infeasible zone grows LOCAL_REPAIR_GROWTH x until it is the whole grid, and the
#: next round starts at the reach that was feasible. Trades the global rounds'
#: re-optimization everywhere for rounds that do not move the checked rest of the plan
#: (reach 32 or 128: five paths within 1 % of each other, compute better either way by path).
#: Side by side on the 64 non-long corpus paths (bench/results/corpus_local_repair.json
#: against corpus_local_repair_before.json): 0 failures, fallbacks, violations either way;
#: whole-job lp compute 0.78x, winding geometric mean -0.24 % (cam-fp-hel45-D30 -11.5 %,
#: D60 -2.9 %; worst +2.6 %, w-hel-R100-a45-sine-2mm-pchip, +0.8 % c-polyline-deg1-30);
#: engine-lp compute 0.96x, -0.08 % (D30 -2.7 %; worst the same two), but the engine's
#: cam-feed-w3-F6000-L150 3.5x compute (more failed seam attempts after its third window).
#: Local rounds at plans from scratch only: windowed / whole job 1.017 on cam-style-R100
#: (its whole job gained 2.1 %, its seam plans 0.7 %). Not for OSQP: its engine on the fast
#: subset but the mill, n-butterfly +18.7 % (8.36 -> 9.93 s, 2.3x compute), c-corners-2d
#: +2.2 %, compute summed 1.13x (bench/results/corpus_osqp_local_repair{,_before}.json)
LOCAL_REPAIR_REACH = 32
LOCAL_REPAIR_GROWTH = 4
#: repair rounds solved on the whole grid before the local ones: the first acts as one more
#: jerk pass at the tightened rows (c-corners-bspline-3d-quintic: 7.435 -> 7.244 s); with
#: every round local that path planned 3.8 % slower than with global rounds, with the
#: first global as fast. 2 or 3 global rounds, on six paths: no better (the pchip helix
#: 6.645 -> 6.510 / 6.477 s, but cam-fp-hel45-D30's whole job 18.86 -> 21.31 / 19.14 s)
GLOBAL_REPAIR_ROUNDS = 1
#: a zone up to this share of the grid is solved as an LP of its own, on the zone's nodes
#: (cold, on `LPPlanner.zone_backend`); a larger one as the whole grid's LP with the held
#: nodes fixed, from the last solve's basis (n-butterfly: zones of 1,100 of 1,476 nodes
#: took ~68 ms on their own, ~45 ms warm, a global round ~25 ms; a zone of 66 of 5,635 nodes
#: ~115 ms warm in the whole LP). Global rounds instead of zones over half the grid lost
#: the local rounds' gain on the long whole-job plans, whose excesses are everywhere
ZONE_LP_MAX_SHARE = 0.5

#: `LPPlanner.brake_jerk`: the jerk (fraction of the path jerk along the start's tangent,
#: `start_limits`) of the braking whose feed a moving start may keep above the LP's
#: velocity caps (`_brake_room`): larger is a tighter room, which the LP's jerk rows (0.85
#: of the limits, conservative) cannot follow at 1; smaller lets the plan stay at the
#: limits longer. 0.5 measured on the random moving starts of tests/test_lp_feasibility.py
#: (0.3 the same there) and the dwell layer's cascade (0 fallbacks)
BRAKE_JERK = 0.5
#: the start zone (`_start_zone`) has at least this many nodes and reaches this many
#: braking distances from the start feed (1.0: a start accelerating at 0.9 of the cap
#: conflicted with a repaired row just beyond the zone, tube-1450 s = 1806)
START_ZONE_MIN = 8
ZONE_REACH = 2.0
#: a repair whose tightening makes the LP from a moving start infeasible is tried again
#: with these fractions of it (each factor old * (new / old)^w), before the elastic rows:
#: their slacks took every later repair near the start (the excess grew 1.3x -> 3.7x
#: jmax over 8 rounds, tube-1450 starts at 0.49-0.96 of the cap accelerating at 0.59-0.84
#: of the path acceleration, the seeded fuzz of tests/test_lp_feasibility.py); with
#: (0.5, 0.25, 0.125) those five starts plan, with (0.75, 0.5, 0.25) three of them fail.
#: Each fraction tried costs one LP. Only the tightening within the start zone
#: (`_start_zone`) is backed off, where it can conflict with the start state; beyond it
#: the repair keeps its whole tightening (backed off as well, on the dwell layer's
#: window with a 5 mm grid the repair of an excess 1569 mm beyond the start got 1/8 of
#: its cut, as did the three rounds after it, and the plan failed after 8 repairs; now
#: it plans after 5, `test_dwell_layer_window_braking_into_its_turnaround_plans`).
REPAIR_BACKOFF = (0.5, 0.25, 0.125)
#: a repair cuts the velocity factor by at least this (acceleration and jerk: 0.97): a
#: velocity excess is the quintic rising ~1e-5 above a node's cap between nodes, and
#: where the LP rides the brake room at the limits themselves (`_brake_room`) a 3 % cut
#: made it infeasible (tube-1450, a start at 628 mm/s accelerating at 1735 mm/s^2)
VEL_CUT = 0.998
#: a jerk pass whose solution lies below 1 / RELINEARIZE_RATIO of its linearization point
#: q* at some free node gets up to RELINEARIZE_EXTRA more passes, each linearized at the
#: last solution: the tangent row at q* allows |jerk| <= J (3/2 - q/(2 q*)) sqrt(q/q*)
#: at q, 0.15 J at q*/100, so a q* far above the solution pins the node near 0 (measured:
#: the dwell layer through the engine, a seam linearized at the upper bounds left the
#: nodes beside its dwell at 1-4 mm/s, intervals of 1-2.6 s, 18.0 s for a 6.7 s window)
RELINEARIZE_RATIO = 10.0
RELINEARIZE_EXTRA = 2
#: ... when the intervals next to such nodes take more than this fraction of the pass's
#: travel time (trades compute for time: on the fast corpus every pass for a smaller
#: share gained < 0.1 % and tripled the replan p99 of c-corners-bspline-2d)
RELINEARIZE_SHARE = 0.02
#: ... on LPs of at most this many nodes (None: any size). Repairs get them too (without:
#: c-corners +0.96 %, the butterfly 7.55 s against 6.74 s). Trades the whole-job LP's
#: compute for its plan; the service's windows (300-1,600 nodes) never reached the old cap
#: of 4000, set when a pass of a CAM program's ~10k-node whole job cost 10-18 s of HiGHS.
#: Since the carried basis and the tighter tolerance (stop 42), measured on the corpus's
#: 17 longest whole jobs (bench/results/lp_whole_relinearize.json): without a cap the
#: fiberpath programs' plans are 3-21 % shorter (cam-fp-hel45-D60 59.18 -> 46.61 s, within
#: 2.8 % of its windowed plan instead of 30.5 % above it) for 1.1-6.5x the CPU (hoop-hel45
#: 7 -> 47 s), the other 10 unchanged to 0.1 %
RELINEARIZE_MAX_NODES: int | None = None
#: a jerk pass that stalls in a dip (`stall_dips`) is solved once more with q* there at most
#: this times `geometric_jerk_cap`, before `_unstall`. Why: at the fiberpath programs'
#: turnarounds the v+a solution is ~10x the q the jerk rows allow (q* 15,000 against
#: ~1,700 mm^2/s^2 on cam-fp-hel45-D60), the first pass dips to q = 0 there, and
#: `_unstall` took 5-6 solves to lift it: 122 such stalls on the 64 non-long paths, 16 s of
#: the engine's 135 s compute. 1.0: the tangent there then admits up to 3x the cap, above
#: the ~0.6x D60's turnarounds plan at. Side by side on the 64 non-long paths
#: (`corpus_stall_recap_{before,after}.json`): engine-lp compute 0.92x, whole-job lp 0.76x,
#: winding -0.02 % / -0.06 % (worst cam-fp-hel45-D60 +0.7 % / +2.1 %, best the dwell cone
#: -1.7 %, cam-fp-cone's whole job -2.6 %). Capped everywhere, not only at a stall, the
#: linearization slowed bends the LP passes above that feed: the polar dome +2.4 %.
STALL_RECAP = 1.0
#: a free node at q at most this times the largest upper bound has stalled (`_unstall`)
STALLED_SHARE = 1e-9
#: rest-to-rest stretches of more LP nodes than this are not planned by the transient
#: planner (`rest_splice`; a compute bound: on the corpus's paths with rest points its
#: plan won on stretches of 28-56 nodes (c-polyline-deg1-30's moves, c-near-cusp-bspline,
#: c-short-winder-0p8mm, one of 34 on c-corners-bspline-3d-quintic) and lost on every one
#: of 81-198 nodes (the B-spline corners, the cusp cycloids), at 0.1-0.8 s of compute each
#: against the LP's 0.1-1 s for the whole path)
SPLICE_MAX_NODES = 64


@dataclass(frozen=True)
class SolverDefaults:
    """The `LPPlanner` settings whose defaults (None arguments) differ between the
    solvers; each is documented, with why OSQP differs, in `LPPlanner`'s docstring."""

    local_repair: int
    seam_va_pass: bool
    seam_passes: int
    stall_recap: bool
    limit_curve_grid: bool
    axis_jerk_change: bool


#: HiGHS (highspy, scipy's HiGHS, "highs-milp"): the settings as measured on the corpus
HIGHS_DEFAULTS = SolverDefaults(local_repair=LOCAL_REPAIR_REACH, seam_va_pass=True,
                                seam_passes=SEAM_PASSES, stall_recap=True,
                                limit_curve_grid=True, axis_jerk_change=False)
#: OSQP: each setting as before the change that HiGHS got (with it, OSQP's ADMM did not
#: converge, or planned slower: `LPPlanner`'s docstring says where)
OSQP_DEFAULTS = SolverDefaults(local_repair=0, seam_va_pass=False, seam_passes=1,
                               stall_recap=False, limit_curve_grid=False,
                               axis_jerk_change=True)


def solver_defaults(solver: str) -> SolverDefaults:
    """The defaults of `solver` (`SolverDefaults`)."""
    return OSQP_DEFAULTS if solver == "osqp" else HIGHS_DEFAULTS


def pinned_share(s: np.ndarray, q: np.ndarray, pinned: np.ndarray) -> float:
    """Travel time (s) of the grid intervals with a pinned node at either end."""
    if not np.any(pinned):
        return 0.0
    v = np.sqrt(np.maximum(q, 0.0))
    vsum = v[:-1] + v[1:]
    touch = pinned[:-1] | pinned[1:]
    with np.errstate(divide="ignore"):
        dt = np.where(vsum > 0, 2.0 * np.diff(s) / vsum, np.inf)
    return float(np.sum(dt[touch]))


def geometric_jerk_cap(geo: GridGeometry, jmax: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Per node, the q = v^2 (path units^2 / s^2) at which the geometric jerk x_sss v^3
    alone reaches scale_i jmax_k on some axis k: min_k (scale_i jmax_k / |x_sss,k|)^(2/3)
    (inf where no axis bends). Not a bound (the path acceleration and jerk terms can
    cancel it), an estimate of the feed at which the jerk rows hold a bend."""
    with np.errstate(divide="ignore"):
        v = np.cbrt(scale[:, None] * jmax[None, :] / np.abs(geo.d3))
    return np.min(v, axis=1) ** 2


def stall_dips(q: np.ndarray, q_star: np.ndarray, stalled: np.ndarray) -> np.ndarray:
    """The nodes of each run of nodes solved below 1 / RELINEARIZE_RATIO of their
    linearization point q* that holds a `stalled` node (a boolean mask): the dip of a
    jerk pass linearized far above the feed its rows then allow."""
    low = q * RELINEARIZE_RATIO < q_star
    edges = np.flatnonzero(np.diff(np.concatenate([[0], low.astype(np.int8), [0]])))
    out = np.zeros(q.size, dtype=bool)
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if stalled[a:b].any():
            out[a:b] = True
    return out


def lift_dips(q: np.ndarray, q_hi: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """The velocity+acceleration solution q as the jerk rows' linearization point: every
    free node (not `fixed`, a boolean mask) more than RELINEARIZE_RATIO below both
    neighbours raised to the lower of them, at most to its bound q_hi (path
    units^2 / s^2).

    Why: the acceleration rows take q' from central differences, which do not see a
    node-to-node zig-zag of q, so the v+a LP's vertex may alternate between high values
    and ~0 on an unequally spaced grid (issue 13: c-fourier-xc on the limit-curve grid,
    v* = 739, 0, 823 mm/s at s = 11632 mm, where nothing slows the path); the tangent
    jerk row at q* ~ 0 allows at most ~3 q*, pinning the node near rest (the first jerk
    pass 14.85 s against 11.96 s with the dips lifted). Only such deep dips: lifting
    every lower node (also the shallow zig-zags, 355, 434, 370 mm/s) made a repair pass
    of the dwell layer's replan from 959 mm/s stall (an engine fallback), as a tangent
    far above the solution pins a node too (RELINEARIZE_RATIO)."""
    out = q.copy()
    lo = np.minimum(q[:-2], q[2:])
    inner = out[1:-1]
    dip = (inner * RELINEARIZE_RATIO < lo) & ~fixed[1:-1]
    inner[dip] = np.minimum(lo[dip], q_hi[1:-1][dip])
    return out


def places_near(s: np.ndarray, trouble: list[float], s_bad: float) -> int:
    """How many of the earlier places `trouble` lie within STUCK_REACH grid intervals
    (nodes s) of the arc length s_bad (all path units)."""
    near = np.abs(np.searchsorted(s, np.asarray(trouble, dtype=float))
                  - np.searchsorted(s, s_bad))
    return int(np.count_nonzero(near <= STUCK_REACH))


def is_new_place(s: np.ndarray, trouble: list[float], s_bad: float) -> bool:
    """Whether s_bad lies further than STUCK_REACH grid intervals from every earlier
    place `trouble` (`places_near`)."""
    return places_near(s, trouble, s_bad) == 0


def stuck_at(s: np.ndarray, trouble: list[float], s_bad: float) -> bool:
    """Whether s_bad lies within STUCK_REACH grid intervals of at least STUCK_REPEATS of
    the earlier places `trouble` (`places_near`)."""
    return len(trouble) >= STUCK_REPEATS and places_near(s, trouble, s_bad) >= STUCK_REPEATS


#: `LPPlanner.objective` choices, and the floor (fraction of the peak q*) of q* in their
#: weights (a node of q* ~ 0 would get an unbounded weight)
OBJECTIVES = ("distance", "sqrt", "time", "time-late")
OBJECTIVE_FLOOR = 1e-4
#: the default objective since stop 41 (before: "distance"). HiGHS, side by side on the 64
#: non-long corpus paths (bench/results/lp_quality_objective.json, whole-job lp and the
#: engine): 0 failures either way; compute summed 489 -> 240 s (lp) and 291 -> 188 s
#: (engine), worst x real time 0.84 -> 2.0 (lp) and 0.99 -> 1.79 (engine), all on
#: fiberpath CAM programs, where 15-26 jerk passes per window left free nodes at q = 0
#: by "distance" for `_unstall` to lift (about 4 more LP solves each), one by "time"
#: (cam-fp-hel45-D60's three slowest windows, replayed cold); winding time median
#: -0.03 %, worst +3.7 % (c-polyline-deg1-30), best -9.8 % (c-short-bspline-0p05mm).
#: OSQP's engine on the 16 fast paths (lp_quality_osqp_objective.json): 0 failures either
#: way, c-corners-bspline-2d -25 % (6.96 -> 5.21 s), the polar dome -3.7 %, worst +1.8 %
#: (c-cycloid-near-cusp-a0p995); compute summed 212 -> 106 s without the mill, whose
#: first window takes twice as long (216 -> 427 s)
DEFAULT_OBJECTIVE = "time"


def start_limits(geo: GridGeometry, limits: AxisLimits) -> tuple[float, float]:
    """The path acceleration and jerk (path units / s^2, / s^3) the axis limits allow
    along the tangent at the first node, min_k amax_k / |x'_k| and min_k jmax_k / |x'_k|
    (the curvature terms aside): less conservative than `lp.envelope.path_limits`, which
    assumes the worst tangent (tube-1450's strokes: 27700 against 19600 mm/s^3)."""
    return tangent_limits(np.abs(geo.d1[0]), limits)


def _at_path_end(request: PlanRequest) -> bool:
    """Whether the request's window ends where its path does (not a window's provisional
    end inside the path received so far)."""
    return request.s_end >= request.path.length * (1.0 - 1e-12)


def default_grid_step(path: Path, limits: AxisLimits, interval_s: float = 0.0045) -> float:
    """Grid spacing: the distance covered in `interval_s` at the fastest feed the axis
    velocity limits could allow (path units)."""
    return float(interval_s * np.linalg.norm(limits.vmax * path.path_scale))


def worst_place(ratios: SampledRatios, profile: FeedProfile) -> tuple[str, float]:
    """The limit kind (velocity, acceleration, jerk) a checked profile exceeds most, and
    the arc length where it does (path units; `profile` times from its start)."""
    kinds = (("velocity", ratios.vel, ratios.t_vel), ("acceleration", ratios.acc, ratios.t_acc),
             ("jerk", ratios.jerk, ratios.t_jerk))
    peaks = [float(np.max(r)) if np.size(r) else -np.inf for _, r, _ in kinds]
    name, r, t = kinds[int(np.argmax(peaks))]
    t_bad = float(np.asarray(t)[int(np.argmax(r))])
    return name, float(profile.at(np.array([t_bad]))[0, 0])


class LPPlanner:
    """Planner "lp". solver: "highs" (default, the faster one measured: HiGHS kept warm
    between re-solves when `highspy` is installed, else scipy's), "highs-milp" or "osqp".

    grid_step: node spacing in path units (None: `default_grid_step`). max_passes: jerk
    re-linearizations. max_repairs: check/tighten rounds (each re-solves one jerk pass).
    margins: initial factors on (vmax, amax, jmax) in the LP rows (the jerk margin absorbs
    most of the overshoot between nodes, so repairs are rare). jerk_step: the largest
    change of the nodal path jerk's axis term x' j between neighbouring nodes, as a
    fraction of jmax (`rows.jerk_change_rows`; a
    regularizer; where the jerk swings from +J to -J within a few nodes the quintic
    reconstruction overshoots the nodal value: at 0.3 the tubes needed 2-5 repair rounds
    per job, at 0.15 none, for +0.02 % winding time). check_step: spacing of the analytic
    verification, in units of the request's dt. envelope_jerk: factor on the path jerk of
    the start/stop S-curve envelopes (the reconstruction overshoots most on the graded grid
    near rest).
    limit_curve_grid: refine the grid where the limit-curve feed is low
    (`lp.grid.limit_curve_steps`; None: on, except for OSQP, whose ADMM stopped at
    max_iter on the polar dome's refined LPs 5-12 % below HiGHS's objective, against
    0.02 % on the bends-only grid). axis_jerk_change: the jerk-change rows on the whole
    axis jerk, as before issue 13 (`rows.jerk_change_rows`; None: only for OSQP, which did
    not converge with the path-jerk rows on n-butterfly).
    reuse: continue the last plan when a request starts on it (`Seam`, `plan`).
    seam_va_pass: at a seam, solve the velocity+acceleration LP for the jerk rows'
    linearization point beyond the reused nodes (off: the upper bounds there). Why on: a
    frozen seam's fresh nodes begin about one braking distance before the last window's
    end, where the last plan's q no longer applies; tangents at the caps (~3x the feed a
    head accelerating out of a turnaround has) made the first jerk pass infeasible on 120
    of 1,186 frozen attempts of the 64 non-long corpus paths (engine-lp), each then re-solved
    half-frozen; with the v+a solution 78 fail, engine-lp compute 161 -> 131 s side by
    side (0.81x; fiberpath programs 0.56-0.86x), winding geometric mean -0.01 %
    (cam-fp-hel25 -0.8 %, cam-fp-hel45-D30 +0.7 %: its last window's repairs, which move
    it as much with seam_passes 2-4 alone; `corpus_seam_va_pass_*.json`). None: on, except
    for OSQP (its engine with this and `stall_recap` on the fast subset without the mill:
    c-fourier-xc +17 % and 3.9x the compute, cam-style-R50 +5.9 %, n-butterfly -4.9 %;
    `corpus_osqp_stop48_*.json`). seam_passes: jerk passes of a seam plan's
    first solve (None: `SEAM_PASSES`, except for OSQP: 1). seam_jerk_change: keep the
    jerk-change rows at a seam's first nodes (its head satisfies them). start_relief: nodes
    after a moving start that get the limits themselves (`_relieve_start`). brake_jerk: the jerk
    (fraction of the path jerk at the start) of the braking a moving start may keep above
    the LP's velocity caps (`_brake_room`). elastic: last relaxation of an infeasible LP
    from a moving start (`lp.elastic`; off: such a start fails, the caller falls back).
    objective: the jerk passes' weights c of max c.q: "distance" (c = h),
    "sqrt" (c = h / sqrt(q*)) or "time" (c = h / q*^(3/2), the gradient of the travel
    time sum h / sqrt(q)) at the pass's linearization point q*, floored at
    OBJECTIVE_FLOOR of its peak; "time-late": "time" only where q* is a jerk solution
    (later passes, repairs), "distance" at the v+a solution (DEFAULT_OBJECTIVE: "time";
    bench/lp_quality.py).
    handover: a moving start whose plan still fails is handed over through the transient
    planner's plan to its first zero-acceleration state that the LP plans from
    (`lp.handover`; off: such a start fails, the caller falls back). transient: that
    planner (None: the heuristic at the request's limits, made on first use).
    local_repair: the repair rounds after the first GLOBAL_REPAIR_ROUNDS re-solve only the
    nodes within this many nodes of a sampled excess (`lp.local_repair`; None:
    `LOCAL_REPAIR_REACH`, except for OSQP: 0, every round on the whole grid, as before
    issue 13's stop 47).
    stall_recap: a jerk pass that stalls in a dip far below its linearization point is
    solved once more with the dip linearized at the geometric-jerk feed (`stall_dips`,
    `STALL_RECAP`) before `_unstall` (off: `_unstall` at once, as before stop 48; None:
    on, except for OSQP, as `seam_va_pass`).
    rest_splice: each stretch between two rest points of a plan (`lp.rest_stretches`) is
    planned by the transient planner too, and its plan replaces the LP's there where it is
    faster and passes the LP's check; a replan starting on such a stretch keeps it up to
    its end at rest and plans from there (off: the LP's plans only).
    The settings whose None default differs per solver are tabled in `SolverDefaults`
    (HIGHS_DEFAULTS, OSQP_DEFAULTS).
    """

    name = "lp"

    def __init__(
        self,
        solver: str = "highs",
        grid_step: float | None = None,
        max_passes: int = 1,
        max_repairs: int = 8,
        margins: tuple[float, float, float] = (0.995, 0.98, 0.85),
        verify: bool = True,
        jerk_step: float = 0.15,
        check_step: float = 0.5,
        envelope_jerk: float = 0.7,
        envelope_margin: float = 0.85,
        zone_pad: int = 10,
        free_start_nodes: int = 3,
        reuse: bool = True,
        seam_va_pass: bool | None = None,
        seam_passes: int | None = None,
        seam_jerk_change: bool = True,
        stall_floor: float = 0.1,
        start_relief: int = 2,
        brake_jerk: float = BRAKE_JERK,
        elastic: bool = True,
        objective: str = DEFAULT_OBJECTIVE,
        limit_curve_grid: bool | None = None,
        axis_jerk_change: bool | None = None,
        handover: bool = True,
        transient: Planner | None = None,
        local_repair: int | None = None,
        stall_recap: bool | None = None,
        rest_splice: bool = True,
    ) -> None:
        if objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
        self.objective = objective
        self.handover = handover
        defaults = solver_defaults(solver)
        self.local_repair = defaults.local_repair if local_repair is None else local_repair
        self.transient = transient
        self.start_relief = start_relief
        self.brake_jerk = brake_jerk
        self.elastic = elastic
        self._elastic = 0  # nodes of the elastic start zone in the solve under way (0: none)
        self._relaxed = 0  # nodes of the start zone at the limits themselves (0: none)
        self.stall_floor = stall_floor
        self.reuse = reuse
        self.seam_va_pass = defaults.seam_va_pass if seam_va_pass is None else seam_va_pass
        self.seam_passes = defaults.seam_passes if seam_passes is None else seam_passes
        self.seam_jerk_change = seam_jerk_change
        self.stall_recap = defaults.stall_recap if stall_recap is None else stall_recap
        self.rest_splice = rest_splice
        #: the rest-to-rest stretches planned by the transient planner, ahead of the last
        #: request's start (`lp.rest_stretches`)
        self._stretches: list[Splice] = []
        self._last: LastPlan | None = None
        self._corners: tuple[Path, float, np.ndarray] | None = None
        self._split: np.ndarray | None = None  # `_plan_cold`: split the grid near these s
        self._stuck_rule = False  # `_plan_grid` gives up on stuck repairs (STUCK_REPEATS)
        self.free_start_nodes = free_start_nodes
        self.envelope_margin = envelope_margin
        self.zone_pad = zone_pad
        self.envelope_jerk = envelope_jerk
        self.check_step = check_step
        self.jerk_step = jerk_step
        self.solver = solver
        self.backend = make_backend(solver)
        #: the solver of local repair rounds' zone LPs: its own, so that they leave the
        #: window LPs' warm start (HiGHS's carried basis, OSQP's last solution) as it was
        self.zone_backend = make_backend(solver)
        self.grid_step = grid_step
        self.max_passes = max_passes
        self.max_repairs = max_repairs
        self.margins = margins
        self.verify = verify
        self.limit_curve_grid = (defaults.limit_curve_grid if limit_curve_grid is None
                                 else limit_curve_grid)
        self.axis_jerk_change = (defaults.axis_jerk_change if axis_jerk_change is None
                                 else axis_jerk_change)

    # --- public -----------------------------------------------------------------------
    def plan(self, request: PlanRequest, fixed_head: np.ndarray | None = None) -> PlanResult:
        """Plan [start.s, s_end]. fixed_head: q values to impose on the first nodes
        (the windowed driver passes the committed nodes of the previous window).

        A request that starts on this planner's last plan (same limits, a path that
        agrees with the last one where nodes are reused, the state at start.s equal to
        the plan's to rounding: the service's replans; `seam.find_seam`)
        continues it (`Seam`): first keeping the last plan up to one braking distance
        before the nearer window end and solving only the rest (`_plan_frozen`, as the
        windowed LP commits), then keeping half of that, then re-solving all but the
        seam's first interval; if all fail, the request is planned from scratch."""
        t0 = time.perf_counter()
        splicing = self.rest_splice and fixed_head is None
        kept = splice_at(self._stretches, request) if splicing else None
        if kept is not None:
            result = self._continue_splice(request, *kept)
            if result is not None:
                return PlanResult(result.profile, self.name, time.perf_counter() - t0,
                                  result.info)
        seam = self.find_seam(request) if fixed_head is None and self.reuse else None
        result = None
        last = self._last
        if seam is not None:
            for attempt in (self._plan_frozen, self._plan_half_frozen, self._plan_seam):
                try:
                    result = attempt(request, seam)
                    break
                except PlanningError:
                    self._last = last
        if result is None:
            try:
                result = self._plan_released(request, fixed_head)
            except PlanningError as exc:
                if not (self.handover and fixed_head is None and request.start.v > REST):
                    raise
                result = plan_handed_over(request, self._transient(), partial(
                    self._plan_released, fixed_head=None), exc)
        if splicing:
            result = self._splice_rests(request, result)
        return PlanResult(result.profile, self.name, time.perf_counter() - t0, result.info)

    def _continue_splice(self, request: PlanRequest, kept: Splice, t: float
                         ) -> PlanResult | None:
        """A replan from time t of the kept stretch `kept`: the stretch's plan from there
        to its end at rest, then a plan from rest there. None where the stretch's end is
        no longer a rest of the request: the request ends there while moving, or goes on
        past an end that was the end of the path received so far (a streamed job's next
        segments came in; the request is then planned as any other)."""
        head = slice_profile(kept.profile, t)
        tol = 1e-12 * max(abs(kept.s1), 1.0)
        if request.s_end <= kept.s1 + tol:
            if request.v_end > REST:
                return None
            return PlanResult(head, self.name, 0.0, {"rest_splice": {"kept_from": t}})
        h = self._grid_step(request)
        if not np.any(np.abs(self.corners(request.path, h) - kept.s1) <= 1e-9 * max(
                abs(kept.s1), 1.0)):
            return None
        rest = self.plan(replace(request, start=PathState(kept.s1)))
        self._stretches.append(kept)  # that plan started past it: replans may start in it
        info = dict(rest.info)
        info["rest_splice"] = {**info.get("rest_splice", {}), "kept_from": t}
        return PlanResult(concatenate([head, rest.profile]), self.name, 0.0, info)

    def _splice_rests(self, request: PlanRequest, result: PlanResult) -> PlanResult:
        """`result` with each rest-to-rest stretch of the LP's plan (`lp.rest_stretches`)
        replaced by the transient planner's plan of it where that is faster and passes
        the LP's check (`_checked_ratios`). The stretches planned are kept for replans:
        those ahead of the request's start (`_stretches`)."""
        last = self._last
        ahead = [sp for sp in self._stretches if sp.s1 > request.start.s]
        self._stretches = ahead
        if (last is None or last.request.path is not request.path
                or last.request.s_end != request.s_end):
            return result  # e.g. a handed-over transient that is the whole plan
        spans = rest_spans(last, last.request.start.v <= REST,
                           request.v_end <= REST and _at_path_end(request))
        if not spans:
            return result
        times = node_times(last) + (result.profile.duration - last.profile.duration)
        s_tol = 1e-9 * max(request.path.length, 1.0)
        swaps, saved, planned = [], 0.0, 0
        for i, j in spans:
            t_a, t_b = float(times[i]), float(times[j])
            if j - i + 1 > SPLICE_MAX_NODES or t_a < -1e-12:
                continue  # too long, or before the request's start (a seam's first node)
            s_a, s_b = float(last.geo.s[i]), float(last.geo.s[j])
            s_at = result.profile.at(np.array([max(t_a, 0.0), t_b]))[0]
            if abs(s_at[0] - s_a) > s_tol or abs(s_at[1] - s_b) > s_tol:
                continue  # the result is not the LP plan's tail there
            sp = find_splice(ahead, request, s_a, s_b)
            if sp is None:
                sp = self._plan_stretch(request, last.geo.take(slice(i, j + 1)))
                planned += 1
            faster = sp.profile is not None and sp.profile.duration < t_b - t_a
            if faster:
                assert sp.profile is not None
                swaps.append((max(t_a, 0.0), t_b, sp.profile))
                saved += t_b - t_a - sp.profile.duration
            marked = sp if sp.used == faster else replace(sp, used=faster)
            self._stretches = [x for x in self._stretches if x is not sp] + [marked]
        if not swaps:
            return result
        info = dict(result.info)
        info["rest_splice"] = {"stretches": len(swaps), "saved_s": saved,
                               "planned": planned}
        return PlanResult(swap_spans(result.profile, swaps), self.name, 0.0, info)

    def _plan_stretch(self, request: PlanRequest, geo: GridGeometry) -> Splice:
        """The transient planner's plan of the rest-to-rest stretch over the nodes `geo`,
        if it passes the LP's check (`_checked_ratios`) on those nodes."""
        sub = PlanRequest(request.path, request.limits, PathState(float(geo.s[0])),
                          float(geo.s[-1]), 0.0, request.feed_cap, request.dt)
        try:
            plan = self._transient().plan(sub)
        except PlanningError:
            return Splice(sub, geo, None)
        if plan.info.get("verified") is False:
            return Splice(sub, geo, None)
        if interior_worst(self._checked_ratios(sub, plan.profile, geo),
                          plan.profile.duration) > 1.0:
            return Splice(sub, geo, None)
        return Splice(sub, geo, plan.profile)

    def _transient(self) -> Planner:
        """The planner of a moving start's transient (`lp.handover`): the heuristic at the
        request's own limits (as the engine's fallback plans), made on first use."""
        if self.transient is None:
            from lookahead.planning.heuristic import HeuristicPlanner

            self.transient = HeuristicPlanner(margin=1.0, continue_last=False)
        return self.transient

    def _plan_released(self, request: PlanRequest, fixed_head: np.ndarray | None
                       ) -> PlanResult:
        """`_plan_cold`, after the closed-form release of a braking start that ends within
        one grid step (`lp.release`: the grid cannot follow it, its first quintic reversed);
        without it if there is none or the plan after it fails."""
        h = self._grid_step(request)
        release = None if fixed_head is not None else start_release(
            request.path, request.limits, request.start, h, float(request.s_end), request.dt,
            self.corners(request.path, h))
        if release is not None:
            try:
                sub = self._plan_cold(replace(request, start=release.end), None)
            except PlanningError:
                pass
            else:
                info = dict(sub.info)
                info["release"] = {"jerk": release.jerk, "s": release.end.s,
                                   "v": release.end.v}
                if "grid_s" in info:
                    info["grid_s"] = np.concatenate([[request.start.s], info["grid_s"]])
                    info["grid_q"] = np.concatenate([[request.start.v**2], info["grid_q"]])
                return PlanResult(concatenate([release.profile, sub.profile]), self.name,
                                  0.0, info)
        return self._plan_cold(request, fixed_head)

    def _plan_cold(self, request: PlanRequest, fixed_head: np.ndarray | None) -> PlanResult:
        """`_plan_cold_by`; where it fails under an objective other than "distance", once
        more by distance (a random walk of bench/fuzz_paths.py, case 2809: pchip knots
        that cap the feed at 1e-4 units/s, stalls that the time-weighted repairs did not
        lift where the distance-weighted ones did, a 40.9 s plan)."""
        try:
            return self._plan_cold_by(request, fixed_head)
        except PlanningError:
            if self.objective == "distance":
                raise
        objective, self.objective = self.objective, "distance"
        try:
            return self._plan_cold_by(request, fixed_head)
        finally:
            self.objective = objective

    def _plan_cold_by(self, request: PlanRequest, fixed_head: np.ndarray | None
                      ) -> PlanResult:
        """A plan from scratch; if it fails, once more with the jerk margin times
        RETRY_JERK_MARGIN; if its repairs still fail, once more on a grid split 4x where
        they failed (`lp.grid.split_near`, not under a fixed head); if one from rest still
        fails on a short stretch, again on grids 2x, 4x, ... finer while they have at most
        `MAX_REFINED_NODES` intervals: a stretch of a few grid steps (short paths) is
        resolved by too few nodes for the jerk rows between its start and stop S-curves
        (measured: 35-100 mm fits and B-spline pieces).

        The first plan's repairs give up as soon as they are stuck at one place
        (`STUCK_REPEATS`, not under a fixed head or at a seam), and the grid split there
        is tried next; if that fails too, the steps above follow, with every repair round
        (fast corpus: c-corners-bspline-2d, cam-style-R50, c-fourier-xc 2-6 % faster plans
        in 0.3-0.7x the compute; n-butterfly 6.85 s against 6.74 s, a plan that flips
        with HiGHS's pivoting: Devex pricing alone made it 7.07 s)."""
        length = float(request.s_end - request.start.s)
        if not length > 0.0:  # an empty window: refused by the grid, never refined
            raise PlanningError(f"lp: s_end {request.s_end} must exceed start.s "
                                f"{request.start.s}")
        h = self._grid_step(request)
        self._stuck_rule = True  # the first plan only (STUCK_REPEATS)
        try:
            return self._plan(request, fixed_head, None)
        except PlanningError as exc:
            first_error = exc
        finally:
            self._stuck_rule = False
        return self._plan_after(request, fixed_head, first_error, length, h)

    def _plan_after(self, request: PlanRequest, fixed_head: np.ndarray | None,
                    first_error: PlanningError, length: float, h: float) -> PlanResult:
        """`_plan_cold` after its first plan failed with `first_error`."""
        if getattr(first_error, "stuck", False):
            # a bend the grid does not resolve: split there at once; if that fails too,
            # the steps below (with every repair round, as before the stuck rule)
            try:
                return self._plan_split(request, first_error.places)  # type: ignore[attr-defined]
            except PlanningError:
                pass
        margins = self.margins
        try:  # repairs that did not converge: once more with a smaller jerk margin
            self.margins = (margins[0], margins[1], margins[2] * RETRY_JERK_MARGIN)
            try:
                return self._plan(request, fixed_head, None)
            except PlanningError as exc:
                places = getattr(exc, "places", None)
                if fixed_head is None and places is not None:
                    return self._plan_split(request, np.concatenate(
                        [places, getattr(first_error, "places", np.empty(0))]))
                raise
        except PlanningError:
            if (fixed_head is not None or request.start.v > REST
                    or length / (h / 2.0) > MAX_REFINED_NODES):
                raise first_error from None  # a moving start: the caller's fallback
        finally:
            self.margins = margins
        finer = h / 2.0
        while True:
            try:
                return self._plan(request, fixed_head, None, grid_step=finer)
            except PlanningError:
                finer /= 2.0
                if length / finer > MAX_REFINED_NODES:
                    raise

    def _plan_split(self, request: PlanRequest, places: np.ndarray,
                    seam: Seam | None = None) -> PlanResult:
        """A plan on the grid split near `places` (s, path units): from scratch, or at
        `seam` with only its fresh nodes split."""
        self._split = places
        try:
            return self._plan(request, None, seam)
        finally:
            self._split = None

    def _plan_seam(self, request: PlanRequest, seam: Seam) -> PlanResult:
        return self._plan_on_seam(request, seam)

    def _plan_on_seam(self, request: PlanRequest, seam: Seam) -> PlanResult:
        """`_plan` at a seam, with the stuck rule of a plan from scratch (`_plan_cold`):
        repairs stuck at one place give up at once for the seam's fresh grid split there
        (`lp.grid.split_near`, the reused nodes untouched); if that fails too, the plain
        seam plan with every repair round (as before the rule).

        Why: the whole-job LP splits its grid where repairs are stuck (the near-stops of
        c-fourier-xc at s = 11309 and 11585), a window's seam plan did not: it tightened
        the same nodes 5 times (jerk factors ~0.6 there) and planned the dip 20 % slower,
        0.12 s of the windowed LP's 0.65 % over the whole-job LP (issue 13)."""
        if seam.reuses_all:
            return self._plan(request, None, seam)
        self._stuck_rule = True
        try:
            return self._plan(request, None, seam)
        except PlanningError as exc:
            if not getattr(exc, "stuck", False):
                raise
            places = exc.places  # type: ignore[attr-defined]
        finally:
            self._stuck_rule = False
        try:
            return self._plan_split(request, places, seam)
        except PlanningError:
            pass
        return self._plan(request, None, seam)

    def _plan_half_frozen(self, request: PlanRequest, seam: Seam) -> PlanResult:
        return self._plan_frozen(request, seam, back=(seam.n_reuse - FIXED_NODES) // 2)

    def _plan_frozen(self, request: PlanRequest, seam: Seam, back: int = 0) -> PlanResult:
        """The last plan kept from the seam up to its node first + n_reuse - FIXED_NODES
        - back, then a plan from there (a seam at that node, its first interval exact):
        only the new part is solved and verified."""
        last = seam.last
        i = seam.first
        j0 = i + seam.n_reuse - FIXED_NODES - back
        if j0 <= i or seam.reuses_all:
            return self._plan_on_seam(request, seam)
        sub = self._plan_on_seam(request, Seam(last, j0, FIXED_NODES, 0.0))
        assert self._last is not None
        self._last = join_last(last, i, j0, self._last, request)
        full = self._last.profile
        info = dict(sub.info)
        info["seam"] = {"reused_nodes": seam.n_reuse, "t_cut": seam.t_cut, "frozen": j0 - i}
        info["grid_s"], info["grid_q"] = self._last.geo.s, self._last.q
        return PlanResult(slice_profile(full, seam.t_cut), self.name, 0.0, info)

    def forget(self) -> None:
        """Drop the last plan and the solver's carried bases (the next request is planned
        from scratch, whatever was planned before)."""
        self._last = None
        self._stretches = []
        for backend in (self.backend, self.zone_backend):
            forget = getattr(backend, "forget", None)
            if callable(forget):
                forget()

    def find_seam(self, request: PlanRequest) -> Seam | None:
        """The seam with the last plan if the request starts on it (`seam.find_seam`)."""
        return find_seam(self._last, request)

    def _plan(self, request: PlanRequest, fixed_head: np.ndarray | None,
              seam: Seam | None, grid_step: float | None = None) -> PlanResult:
        """One plan: the grid (fresh, or continuing the seam's), the LP, the check/repair
        loop. Remembers the result as the last plan. A seam with the last plan's end is
        the rest of the last plan (verified already): no LP."""
        if seam is not None and seam.reuses_all:
            return self._rest_of_last(seam)
        if seam is None:
            s, stop_idx = self.grid(request, grid_step)
            geo = self.geometry(request.path, s)
            tight = Tightening.uniform(s.size, *self.margins)
            self._pretighten(request, geo, tight, stop_idx)
            self._relieve_start(request, tight)
            head, q_star_head, a_start, t_cut = fixed_head, None, request.start.a, 0.0
        else:
            geo, stop_idx, tight = self._seam_grid(request, seam)
            s = geo.s
            head = seam.last.q[seam.first:seam.first + min(FIXED_NODES, seam.n_reuse)]
            q_star_head = self._seam_linearization(request, seam, s)
            a_start, t_cut = float(seam.last.a[seam.first]), seam.t_cut
        self._elastic = self._relaxed = 0
        try:
            return self._plan_grid(request, geo, tight, stop_idx, head, seam, q_star_head,
                                   a_start, t_cut)
        finally:
            self._elastic = self._relaxed = 0

    def _plan_grid(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                   stop_idx: np.ndarray, head: np.ndarray | None, seam: Seam | None,
                   q_star_head: np.ndarray | None, a_start: float, t_cut: float
                   ) -> PlanResult:
        """`_plan` on its grid: the LP (elastic near a moving start if the LP is
        infeasible, `_start_zone`), then the check/repair loop."""
        s = geo.s
        can_relax = seam is None and head is None and request.start.v > REST
        # jerk passes of the first solve (and of a repair solved afresh like it)
        first_passes = None if seam is None else max(self.seam_passes, self.max_passes)

        def solve(before: Tightening | None = None, **kw) -> GridPlan:
            """The LP at `tight`; `before`: the factors before a repair's tightening."""
            try:
                return self.solve_grid(request, geo, tight, stop_idx, head,
                                       start_envelope=seam is None, **kw)
            except PlanningError:
                if kw.get("hold") is not None:
                    raise  # a local repair round: `_repair_round` widens its zone
                if kw.get("start_q") is not None:
                    # a repair linearized at the last plan whose jerk passes all stalled:
                    # linearize afresh, from the v+a solution at the tightened limits
                    # (`_relinearized_repair`)
                    fresh = self._relinearized_repair(request, geo, tight, stop_idx, head,
                                                      seam is None, first_passes, kw)
                    if fresh is not None:
                        return fresh
                if not can_relax or self._elastic:
                    raise
            if before is not None:  # a repair: fractions of its tightening in the start
                # zone (REPAIR_BACKOFF), the whole of it beyond
                full = (tight.vel.copy(), tight.acc.copy(), tight.jerk.copy())
                zone = self._start_zone(request, geo)
                for w in REPAIR_BACKOFF:
                    for mine, old, new in zip((tight.vel, tight.acc, tight.jerk),
                                              (before.vel, before.acc, before.jerk), full,
                                              strict=True):
                        mine[:zone] = old[:zone] * (new[:zone] / old[:zone]) ** w
                    try:
                        return self.solve_grid(request, geo, tight, stop_idx, head,
                                               start_envelope=True, **kw)
                    except PlanningError:
                        pass
                tight.vel[:], tight.acc[:], tight.jerk[:] = full
            # relaxation, in this order (module docstring): (1) the start zone gets the
            # limits themselves (factors 1): the start state may come from a plan at the
            # full limits (the heuristic's), or the v+a linearization point lies too far
            # above a jerk-limited braking (`_remargin`); (2) its rows become elastic
            # (`lp.elastic`), a feasible LP whatever the start. (Dropping the jerk-change
            # rows over the zone as well let the nodal jerk zig-zag: 3x jmax between the
            # nodes.)
            zone = self._start_zone(request, geo)
            # not after a repair: factors 1 would undo the repair's tightening there
            # (measured: a replan from an accelerating start on tube-1450, its repairs
            # going round at +30 % jerk until the plan gave up; the elastic rows keep it)
            if not self._relaxed and before is None:
                self._relaxed = zone
                margins = (tight.acc[:zone].copy(), tight.jerk[:zone].copy())
                tight.acc[:zone] = 1.0
                tight.jerk[:zone] = 1.0
                try:
                    relaxed = self.solve_grid(request, geo, tight, stop_idx, head,
                                              start_envelope=True, **kw)
                except PlanningError:
                    if not self._use_elastic:
                        raise
                else:
                    return self._remargin(request, geo, tight, stop_idx, head, relaxed,
                                          zone, margins)
            if not self._use_elastic:
                raise PlanningError("lp: the LP from the moving start is infeasible")
            self._elastic = zone
            return self.solve_grid(request, geo, tight, stop_idx, head, start_envelope=True,
                                   **kw)

        plan = solve(q_star_head=q_star_head, passes=first_passes)
        allowance = self._start_allowance(request, geo, tight) if seam is None else None
        acc_allowance = self._start_acc_allowance(request, geo) if seam is None else None
        knotty = request.path.continuity() < 2
        repairs = 0
        worst = float("nan")
        trouble: list[float] = []  # where each repair round's worst excess was (s)
        reach = self.local_repair  # of the next local repair round's zones (0: global)
        lowest, free = np.inf, 0  # the smallest worst ratio so far; rounds not counted
        may_split = self._stuck_rule and (seam is not None or head is None)
        while True:
            full = self._profile(request, plan, a_start)
            profile = slice_profile(full, t_cut) if t_cut > 0.0 else full
            if not self.verify:
                break
            ratios = self._checked_ratios(request, profile, geo, knotty)
            if allowance is not None:
                s_t = profile.at(ratios.t_vel)[0]
                ratios = replace(ratios, vel=ratios.vel / np.interp(s_t, geo.s, allowance))
            if acc_allowance is not None:
                t_first = float(profile.s_of_t.x[1] - profile.s_of_t.x[0])
                ratios = replace(ratios, acc=np.where(ratios.t_acc <= t_first,
                                                      ratios.acc / acc_allowance, ratios.acc))
            if t_cut > 0.0:  # times on the un-cut profile, whose pieces are the intervals
                ratios = replace(ratios, t_vel=ratios.t_vel + t_cut,
                                 t_acc=ratios.t_acc + t_cut, t_jerk=ratios.t_jerk + t_cut)
            worst = ratios.worst
            if worst <= 1.0:
                break
            kind, s_bad = worst_place(ratios, full)
            stuck = may_split and stuck_at(s, trouble, s_bad)
            if repairs > 0 and worst < lowest and is_new_place(s, trouble, s_bad):
                free += 1  # the last round made progress (REPAIRS_PER_BUDGET)
            lowest = min(lowest, worst)
            if (stuck or repairs - free >= self.max_repairs
                    or repairs >= REPAIRS_PER_BUDGET * self.max_repairs
                    or (repairs >= HOPELESS_AFTER and worst > HOPELESS_RATIO)):
                exc = PlacedPlanningError(
                    f"lp: sampled profile still exceeds the {kind} limit by "
                    f"{100 * (worst - 1):.1f} % after {repairs} repairs"
                    + (" (stuck there)" if stuck else ""), s_bad)
                exc.places = np.array([*trouble, s_bad])  # type: ignore[attr-defined]
                exc.stuck = stuck  # type: ignore[attr-defined]
                raise exc
            trouble.append(s_bad)
            before = Tightening(tight.vel.copy(), tight.acc.copy(), tight.jerk.copy())
            self._tighten(tight, ratios, full, s, request.dt)
            # at a seam, q_star_head keeps the jerk-change rows on its first nodes as in
            # the first solve (without: the nodal jerk zig-zagged there, round after
            # round, until the LP was infeasible; tests/test_lp_seam_repairs.py)
            local = repairs >= GLOBAL_REPAIR_ROUNDS
            plan, reached = self._repair_round(solve, before, plan, ratios, full,
                                               q_star_head, reach if local else 0)
            reach = reached if local else reach
            repairs += 1
        a_end = 0.0  # at rest, or at v_end with path acceleration 0
        self._last = LastPlan(request, geo, plan.q, node_accelerations(s, plan.q, a_start, a_end),
                              tight, stop_idx, full)
        info = {
            "solver": self.solver,
            "nodes": int(s.size),
            "seam": None if seam is None else {"reused_nodes": seam.n_reuse,
                                               "t_cut": seam.t_cut},
            "pass_times_s": plan.pass_times,
            "solver_ms": plan.solver_ms,
            "statuses": plan.statuses,
            "repairs": repairs,
            "worst_ratio": worst,
            "grid_s": s,
            "grid_q": plan.q,
        }
        return PlanResult(profile, self.name, 0.0, info)

    def _relinearized_repair(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                             stop_idx: np.ndarray, head: np.ndarray | None,
                             start_envelope: bool, passes: int | None, kw: dict
                             ) -> GridPlan | None:
        """A repair round (`solve_grid`'s keywords `kw`) again, its jerk rows linearized
        as the first solve's (the v+a solution; at a seam the last plan's q on the reused
        nodes and the upper bounds beyond) instead of at the last plan's solution
        everywhere, with the first solve's `passes`; None if that fails too.
        The last plan's q can pin a stretch at near-zero feed: a tangent row at a tiny q*
        allows at most 3 q*, and the 1/h^2 of a refined grid passes the pin on to the
        neighbours, so the stall moves by a node per pass and `STALL_PASSES` cannot lift it
        (fuzz case (3, 2, 35, 1.8786, 0.0, 'pchip'): a C1 knot capping 4 nodes 0.25 um
        apart at 0.03 mm/s)."""
        try:
            return self.solve_grid(request, geo, tight, stop_idx, head,
                                   start_envelope=start_envelope,
                                   **{**kw, "start_q": None, "passes": passes,
                                      "hold": None})
        except PlanningError:
            return None

    @staticmethod
    def _rest_of_last(seam: Seam) -> PlanResult:
        last = seam.last
        x = last.profile.s_of_t.x
        profile = slice_profile(last.profile, float(x[seam.first] - x[0]) + seam.t_cut)
        info = {"seam": {"reused_nodes": seam.n_reuse, "t_cut": seam.t_cut, "solved": False},
                "nodes": seam.n_reuse, "repairs": 0, "grid_s": last.geo.s[seam.first:],
                "grid_q": last.q[seam.first:]}
        return PlanResult(profile, "lp", 0.0, info)

    def _seam_linearization(self, request: PlanRequest, seam: Seam, s: np.ndarray
                            ) -> np.ndarray:
        """The jerk rows' linearization point on the first nodes of a seam's grid: the
        last plan's q on the reused nodes and, on fresh nodes up to where the last plan
        began braking for its window end, its q interpolated (tangents at the solution
        being continued keep it feasible; at the upper bounds, continuing a hard
        acceleration from the seam was infeasible)."""
        last = seam.last
        q = last.q[seam.first:seam.first + seam.n_reuse]
        A, J = path_limits(request.path, request.limits)
        brake = braking_distance(float(np.sqrt(np.max(last.q))), A * self.margins[1],
                                 J * self.envelope_jerk * self.margins[2] * self.envelope_margin)
        fresh = s[seam.n_reuse:]
        fresh = fresh[fresh <= last.request.s_end - brake]
        return np.concatenate([q, np.interp(fresh, last.geo.s, last.q)])

    def _checked_ratios(self, request: PlanRequest, profile: FeedProfile, geo: GridGeometry,
                        knotty: bool | None = None) -> SampledRatios:
        """The sampled check of `profile` (from request.start.s) over the nodes `geo`:
        axis velocity, acceleration and jerk over their limits (`analytic_ratios`), the
        feed over the request's feed cap, the checker's extra jerk at C1 knots (`knotty`:
        the path is C1; None: ask it)."""
        ratios = analytic_ratios(request.path, profile, request.limits, geo,
                                 self.check_step * request.dt)
        if request.feed_cap is not None:
            # the feed cap holds at the nodes only (q <= cap^2): between them the
            # reconstruction overshot it by up to 3.4 % (the 20k-line program at F6000)
            s_t, v_t = profile.at(ratios.t_vel)[:2]
            ratios = replace(ratios, vel=np.maximum(
                ratios.vel, v_t / (request.feed_cap.at(s_t) * (1.0 + FEED_CAP_TOL))))
        if knotty is None:
            knotty = request.path.continuity() < 2
        if knotty:
            s_t, v_t = profile.at(ratios.t_jerk)[:2]
            extra = knot_fd_ratio(request.path, request.limits, request.dt, s_t, v_t)
            if extra is not None:
                ratios = replace(ratios, jerk=ratios.jerk + extra)
        return ratios

    def _grid_step(self, request: PlanRequest) -> float:
        """The nominal node spacing for `request` (path units): `grid_step`, else
        `default_grid_step`."""
        return self.grid_step or default_grid_step(request.path, request.limits)

    def corners(self, path: Path, h: float) -> np.ndarray:
        """The rest points: path.corners_s() and the near-reversals the grid of step h
        cannot resolve (`lp.grid.near_reversals`), cached for the last path object and h
        (a replan's path)."""
        if self._corners is None or self._corners[0] is not path or self._corners[1] != h:
            stops = np.concatenate([np.asarray(path.corners_s(), dtype=float),
                                    near_reversals(path, h)])
            self._corners = (path, h, np.unique(stops))
        return self._corners[2]

    def geometry(self, path: Path, s: np.ndarray) -> GridGeometry:
        """Path derivatives at the nodes s (`GridGeometry.sample`)."""
        return GridGeometry.sample(path, s)

    def _seam_grid(self, request: PlanRequest, seam: Seam
                   ) -> tuple[GridGeometry, np.ndarray, Tightening]:
        """The seam's reused nodes, then fresh ones to s_end; the reused nodes keep their
        geometry and tightening, the fresh ones get the margins and the stop pretightening."""
        last = seam.last
        reused = slice(seam.first, seam.first + seam.n_reuse)
        old_stops = last.stop_idx[(last.stop_idx > seam.first)
                                  & (last.stop_idx < seam.first + seam.n_reuse)] - seam.first
        h = self._grid_step(request)
        corners = self.corners(request.path, h)
        if seam.reuses_all:  # the same end: no fresh nodes
            geo, stop_idx = last.geo.take(reused), old_stops
        else:
            s, stop_idx = extend_grid(last.geo.s[reused], float(request.s_end), h,
                                      request.v_end <= REST, corners, old_stops)
            s, stop_idx = self.refine(request.path, s, stop_idx, h, first=seam.n_reuse - 1,
                                      limits=self._grid_limits(request),
                                      feed_cap=request.feed_cap, dt=request.dt)
            if request.feed_cap is not None:
                s, stop_idx = with_breaks(s, stop_idx, request.feed_cap.changes(),
                                          first=seam.n_reuse - 1)
            if self._split is not None:  # `_plan_on_seam`: the fresh nodes only
                k = seam.n_reuse - 1
                tail, tail_stops = split_near(s[k:], stop_idx[stop_idx >= k] - k,
                                              self._split[self._split > s[k]])
                s = np.concatenate([s[:k], tail])
                stop_idx = np.concatenate([stop_idx[stop_idx < k], tail_stops + k])
            geo = GridGeometry.join(last.geo.take(reused),
                                    self.geometry(request.path, s[seam.n_reuse:]))
        tight = Tightening.uniform(geo.n_nodes, *self.margins)
        for mine, theirs in ((tight.vel, last.tight.vel), (tight.acc, last.tight.acc),
                             (tight.jerk, last.tight.jerk)):
            mine[:seam.n_reuse] = theirs[reused]
        self._pretighten(request, geo, tight, stop_idx, first_free=seam.n_reuse)
        return geo, stop_idx, tight

    def grid(self, request: PlanRequest, grid_step: float | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
        """The nodes of the request's stretch and the indices of interior rest nodes
        (grid_step: node spacing, default the planner's)."""
        s0, s1 = float(request.start.s), float(request.s_end)
        if not s1 > s0:
            raise PlanningError(f"lp: s_end {s1} must exceed start.s {s0}")
        h = grid_step or self._grid_step(request)
        corners = self.corners(request.path, h)
        s, stop_idx = build_grid(s0, s1, h, request.start.v <= REST, request.v_end <= REST,
                                 corners)
        s, stop_idx = self.refine(request.path, s, stop_idx, h, limits=self._grid_limits(request),
                                  feed_cap=request.feed_cap, dt=request.dt)
        if request.feed_cap is not None:
            s, stop_idx = with_breaks(s, stop_idx, request.feed_cap.changes())
        if self._split is not None:
            s, stop_idx = split_near(s, stop_idx, self._split)
        return s, stop_idx

    def _grid_limits(self, request: PlanRequest) -> AxisLimits | None:
        """The limits `refine` follows the limit curve of (None: `limit_curve_grid` off)."""
        return request.limits if self.limit_curve_grid else None

    def refine(self, path: Path, s: np.ndarray, stop_idx: np.ndarray, h: float,
               first: int = 0, limits: AxisLimits | None = None,
               feed_cap: FeedCap | None = None, dt: float | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """Finer nodes where the path bends sharply (`lp.grid.refine_grid`), from node
        `first` on, judged on samples FEATURE_SAMPLES per nominal step h apart, and finer
        where a bend hides between two of them (`lp.grid.feature_samples`); with `limits`,
        also where the limit-curve feed is low (`lp.grid.limit_curve_steps`: nodes no
        further apart in time there than h at the top feed), and likewise at the changes
        of `feed_cap` at the lower cap (`lp.grid.break_steps`), and with the sample time
        `dt` too at a C1 path's knots at their caps (`lp.knots.knot_steps`)."""
        lo, hi = float(s[first]), float(s[-1])
        if not hi > lo:
            return s, stop_idx
        s_feat, d = feature_samples(path, lo, hi, h / FEATURE_SAMPLES, s[stop_idx])
        scale = np.asarray(path.path_scale, dtype=float)
        step = feature_steps(s_feat, d[2], d[3], scale, h)
        if limits is not None:
            feed = limit_curve_feed(d[2], d[3], limits.amax, limits.jmax)
            v_top = float(np.linalg.norm(limits.vmax * scale))
            step = np.minimum(step, limit_curve_steps(feed, h, v_top))
        if limits is not None and feed_cap is not None:
            s_feat, step = break_steps(feed_cap, s_feat, step, h, v_top)
        if limits is not None and dt is not None:  # (nothing on a C2 path)
            s_feat, step = knot_steps(path, limits, dt, s_feat, step, h, v_top)
        return refine_grid(s, stop_idx, s_feat, step, first)

    def solve_grid(
        self,
        request: PlanRequest,
        geo: GridGeometry,
        tight: Tightening,
        stop_idx: np.ndarray,
        fixed_head: np.ndarray | None = None,
        start_q: np.ndarray | None = None,
        passes: int | None = None,
        start_envelope: bool = True,
        q_star_head: np.ndarray | None = None,
        hold: np.ndarray | None = None,
    ) -> GridPlan:
        """Velocity+acceleration pass (unless start_q is given), then up to `passes`
        (default max_passes) jerk passes. start_envelope: bound q by the S-curve from the
        start state (not at a seam, whose first nodes are fixed). q_star_head: the jerk
        rows' linearization point on the first nodes (a seam's last solution there; with
        start_q, which then linearizes everywhere, it only says "at a seam": the
        jerk-change rows on the first nodes stay, `seam_jerk_change`). hold: (n,) mask of
        the nodes held at start_q, a local repair round (`lp.local_repair`)."""
        lim = request.limits
        q_hi = np.minimum(self._caps(request, geo, tight),
                          self._envelope(request, geo, tight, stop_idx,
                                         include_start=start_envelope))
        if start_envelope and fixed_head is None and request.start.v > REST:
            # the braking room lifts the caps and the envelopes (`_rest_caps`: how far)
            room = self._brake_room(request, geo, tight)
            q_hi = np.minimum(np.maximum(q_hi, room),
                              self._rest_caps(request, geo, tight, stop_idx, room))
        q_lo = np.zeros_like(q_hi)
        fixed = {0: request.start.v**2, geo.n_nodes - 1: request.v_end**2}
        fixed.update({int(i): 0.0 for i in stop_idx})
        if fixed_head is not None:
            fixed.update({i: float(v) for i, v in enumerate(fixed_head)})
        for i, val in fixed.items():
            q_lo[i] = val
            q_hi[i] = max(val, 0.0)
        base = [acceleration_rows(geo, lim.amax, tight.acc)]
        if request.v_end > REST:  # ends moving: at the feed v_end, path acceleration 0
            base.append(end_acceleration_rows(geo, lim.amax, float(tight.acc[-1])))
            base.append(end_slope_row(geo, 0.0))
        if request.start.v > REST and fixed_head is None:
            base.append(start_slope_row(geo, request.start.a))
            base.append(start_jerk_rows(geo, lim.jmax, float(tight.jerk[0]),
                                        request.start.v, request.start.a))
        weight = np.gradient(geo.s)
        plan = GridPlan(geo.s, np.zeros(geo.n_nodes), np.inf)
        q_star = start_q
        if q_star is None and q_star_head is not None and not self.seam_va_pass:
            q_star = np.concatenate([q_star_head, q_hi[q_star_head.size:]])
        if q_star is None:
            q_star = self._solve(plan, weight, q_lo, q_hi, base, geo.n_nodes, record=False)
            q_star = lift_dips(q_star, q_hi, np.isin(np.arange(geo.n_nodes), list(fixed)))
            if q_star_head is not None:
                q_star = np.concatenate([q_star_head, q_star[q_star_head.size:]])
        q_floor = 1e-6 * float(np.max(q_hi))
        rest = [i for i, val in fixed.items() if val <= REST**2]
        if request.start.v > REST and (q_star_head is None or not self.seam_jerk_change):
            # the moving start's own jerk is whatever its previous plan had: the
            # jerk-change regularizer there made replans from braking states infeasible
            # (not at a seam, whose head satisfies it: its own plan's rows)
            rest += list(range(self.free_start_nodes))
        rest = np.unique(np.array(rest, dtype=int))
        # a local repair round: the nodes held at start_q (not the fixed ones), their
        # bounds, and every pinned value the solutions get exactly
        held, lo, hi, pinned_q = None, q_lo, q_hi, fixed
        if hold is not None and start_q is not None:
            held = hold & ~np.isin(np.arange(geo.n_nodes), list(fixed))
            q_held = np.maximum(start_q, 0.0)
            lo, hi = np.where(held, q_held, q_lo), np.where(held, q_held, q_hi)
            pinned_q = fixed | {int(i): float(q_held[i]) for i in np.flatnonzero(held)}
        best_q, best_t = None, np.inf
        n_passes = passes or self.max_passes
        knot = knot_jumps(request.path, geo.s)
        if knot is not None:
            knot = knot / request.dt
        free = np.ones(geo.n_nodes, dtype=bool)
        free[list(fixed)] = False
        k = 0
        # a pass left stalled under weights other than "distance" is solved again, and
        # the passes after it, with the distance weights before its nodes are
        # re-linearized: at a seam the time weights stem from q* = q_hi beyond the head,
        # and `_unstall` could not lift the stall (w-hel-R100-a45-dwell-2mm's second
        # window: a 14.5 s plan with nodes at q = 0, 5.5 s with the retry; the engine's
        # job 17.1 -> 8.1 s, the distance objective's 8.0 s)
        by_distance = False
        recapped = False  # the one stall re-linearization of this solve (`stall_dips`)
        while True:
            rows = [*base, jerk_rows(geo, lim.jmax, tight.jerk, q_star, q_floor, knot),
                    jerk_change_rows(geo, lim.jmax, q_star, q_floor, self.jerk_step, rest,
                                     axis_jerk=self.axis_jerk_change)]
            if held is not None:
                rows = [held_rows(r, q_held, held) for r in rows]
            w = (weight if by_distance else
                 self._pass_weight(weight, q_star, k > 0 or start_q is not None))
            q = self._solve(plan, w, lo, hi, rows, geo.n_nodes, record=True, held=held)
            for i, val in pinned_q.items():  # exactly, not to the solver's rounding
                q[i] = val
            if not recapped and held is None and self.stall_recap:
                # a stall in a dip below a linearization far above it: once, the dip
                # linearized at the geometric-jerk feed instead (STALL_RECAP), before
                # `_unstall`'s objectives and floors
                dip = stall_dips(q, q_star, free & (q <= STALLED_SHARE * float(np.max(hi))))
                if dip.any():
                    capped = np.minimum(q_star, STALL_RECAP * geometric_jerk_cap(
                        geo, lim.jmax, tight.jerk))
                    if np.any(dip & (capped < q_star)):  # else the same LP again
                        recapped = True
                        q_star = np.where(dip, capped, q_star)
                        continue
            q = self._unstall(plan, weight, q, lo, hi, rows, pinned_q)
            t = grid_time(geo.s, q)
            plan.pass_times.append(t)
            if (not np.isfinite(t) and best_q is None and not by_distance
                    and self.objective != "distance"):
                by_distance = True
                continue
            if not np.isfinite(t) and best_q is None and k < STALL_PASSES:
                # a stalled run (adjacent free nodes at q = 0) that `_unstall` did not
                # lift: the jerk rows linearized at q_star pin them, so linearize those
                # nodes higher (halfway to q_hi, geometrically) and solve again
                zero = free & (q <= q_floor)
                q_star = np.where(zero, np.sqrt(np.maximum(q_star, q_floor) * q_hi), q_star)
                k += 1
                continue
            if t >= best_t * (1.0 - 1e-4):
                break
            used = np.maximum(q_star, q_floor)
            pinned = free & (q * RELINEARIZE_RATIO < used)
            best_q, best_t = q, t
            # pinned nodes: the next tangent between the last point and the solution (a
            # tangent at the solution itself allows at most 3x it: from below, a node
            # near 0 would climb by 3x per pass)
            q_star = np.where(pinned, np.sqrt(used * np.maximum(q, q_floor)), q)
            k += 1
            extra = ((RELINEARIZE_MAX_NODES is None or geo.n_nodes <= RELINEARIZE_MAX_NODES)
                     and pinned_share(geo.s, q, pinned) > RELINEARIZE_SHARE * t)
            if k >= n_passes + (RELINEARIZE_EXTRA if extra else 0):
                break
        if best_q is None:
            raise PlanningError("lp: the jerk LP has no solution")
        plan.q, plan.time_s = best_q, best_t
        return plan

    # --- internals --------------------------------------------------------------------
    def _pass_weight(self, weight: np.ndarray, q_star: np.ndarray, at_jerk_solution: bool
                     ) -> np.ndarray:
        """A jerk pass's objective weights (`objective`), normalized to sum(weight)."""
        if self.objective == "distance" or (self.objective == "time-late"
                                            and not at_jerk_solution):
            return weight
        ref = np.maximum(q_star, OBJECTIVE_FLOOR * max(float(np.max(q_star)), 1e-300))
        w = weight / (np.sqrt(ref) if self.objective == "sqrt" else ref**1.5)
        return w * (float(np.sum(weight)) / float(np.sum(w)))

    def _unstall(self, plan: GridPlan, weight, q: np.ndarray, q_lo: np.ndarray,
                 q_hi: np.ndarray, rows: list[Rows], fixed: dict[int, float]) -> np.ndarray:
        """Re-solve if a free node got q = 0 (an unplanned stop; next to a rest node, an
        interval that never ends). The objective sum(h q) hardly values the small q
        near rest, and on short paths the linearized jerk rows made the LP trade them
        for the middle (measured: 35-100 mm paths); on wiggly paths (the Fourier and
        butterfly paths of issue 13) it traded a node in a slow stretch, where the rows
        let it reach only ~0.1 % of its velocity cap, for the nodes around it.

        Same rows, other objectives, in this order (each LP is feasible: q = 0 is): (1)
        each node weighed by the travel time its feed saves at the upper bounds,
        h / q_hi^(3/2); (2) the same gradient of sum h / sqrt(q) at the stalled
        solution itself (q floored at `STALL_REF` q_hi), which values a stalled node
        most; (3) a lower bound `stall_floor` q_hi on the stalled nodes, halved while
        it makes the LP infeasible (a floor is only tried, never imposed: before issue 13
        an infeasible floor failed the whole window). Returns the first solution
        without a stall, else the last one (the check then decides)."""
        tiny = STALLED_SHARE * float(np.max(q_hi))
        free = np.ones(q.size, dtype=bool)
        free[list(fixed)] = False

        def stalled(x: np.ndarray) -> np.ndarray:
            return free & (x <= tiny)

        if not np.any(stalled(q)):
            return q

        def timed(ref: np.ndarray) -> np.ndarray:
            w = weight / np.maximum(ref, tiny) ** 1.5
            return w * (float(np.sum(weight)) / float(np.sum(w)))

        def solve(w: np.ndarray, lo: np.ndarray) -> np.ndarray:
            x = self._solve(plan, w, lo, q_hi, rows, q.size, record=True)
            for i, val in fixed.items():
                x[i] = val
            return x

        q = solve(timed(q_hi), q_lo)
        if not np.any(stalled(q)):
            return q
        w = timed(np.maximum(q, STALL_REF * q_hi))
        q = solve(w, q_lo)
        floor = self.stall_floor
        lowest = floor * 0.25 ** (STALL_FLOOR_TRIES - 1)  # the last try's, if all fail

        def floored(bad: np.ndarray, f: float) -> np.ndarray:
            lo = q_lo.copy()
            lo[bad] = np.maximum(lo[bad], f * q_hi[bad])
            return lo

        # the floors accumulate: a floor that lifted some nodes may stall others, and
        # flooring only those let the first ones fall back to 0 (the pocketing
        # program's whole-job LP at jerk margin 0.75: two nodes of a straight line
        # lifted to 0.025 q_hi, then back to 0, "the jerk LP has no solution")
        held = np.zeros(q.size, dtype=bool)
        for k in range(STALL_FLOOR_TRIES):
            bad = stalled(q)
            if not np.any(bad):
                break
            bad |= held
            try:
                q = solve(w, floored(bad, floor))
                held = bad
            except PlanningError:
                floor *= 0.25
                if k == 0 and STALL_FLOOR_TRIES > 2:
                    # a lower floor only relaxes the LP: if the last try's floor is
                    # infeasible on these nodes, so is every try between (measured:
                    # c-corners-bspline-2d's stalls beside its near-reversals failed all
                    # four tries in most passes, 2 solves instead of 4, same result)
                    try:
                        solve(w, floored(bad, lowest))
                    except PlanningError:
                        break
        return q

    def _solve(self, plan: GridPlan, weight, q_lo, q_hi, rows: list[Rows], n: int,
               record: bool, held: np.ndarray | None = None) -> np.ndarray:
        """The LP max weight.q at these bounds and rows (rows on fixed nodes only are
        dropped). held: nodes fixed at q_lo (= q_hi) for a local repair round; the LP is
        then solved on the other nodes alone (`lp.local_repair.zone_rows`), or, if they
        are more than ZONE_LP_MAX_SHARE of the grid, as the whole LP in the last solve's
        shape (its rows on held nodes only kept), which HiGHS starts from its basis."""
        if held is None or not held.any() or self._elastic:
            return self._solve_lp(plan, weight, q_lo, q_hi, Rows.stack(rows, n), plan.s,
                                  self.backend)
        zone = ~held
        if np.mean(zone) > ZONE_LP_MAX_SHARE:  # the rows through held nodes only stay
            return self._solve_lp(plan, weight, q_lo, q_hi, Rows.stack(rows, n), plan.s,
                                  self.backend, fixed=(q_lo >= q_hi) & zone)
        q = q_lo.copy()
        q[zone] = self._solve_lp(plan, weight[zone], q_lo[zone], q_hi[zone],
                                 zone_rows(Rows.stack(rows, n), held, q_lo), plan.s[zone],
                                 self.zone_backend)
        return q

    def _solve_lp(self, plan: GridPlan, weight, q_lo, q_hi, rows: Rows, nodes: np.ndarray,
                  backend, fixed: np.ndarray | None = None) -> np.ndarray:
        """`_solve` on one block of rows by `backend`, the variables at `nodes` (path
        units); rows on `fixed` variables only (default: q_lo >= q_hi) are dropped."""
        fixed = q_lo >= q_hi if fixed is None else fixed
        lp = ScaledLP.build(weight, q_lo, q_hi, free_rows(rows, fixed), nodes=nodes)
        if self._elastic:
            lp, _ = elastic_lp(lp, self._elastic)
        t0 = time.perf_counter()
        out = backend.solve(lp)
        plan.solver_ms.append(1e3 * (time.perf_counter() - t0))
        plan.statuses.append(out.status)
        if not out.ok:
            raise PlacedPlanningError(f"lp: {self.solver} returned {out.status}",
                                      float(plan.s[0]))
        return out.q[:nodes.size]

    def _remargin(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                  stop_idx: np.ndarray, head: np.ndarray | None, relaxed: GridPlan,
                  zone: int, margins: tuple[np.ndarray, np.ndarray]) -> GridPlan:
        """After the start zone's relaxation to the limits planned (`relaxed`): the LP at
        the zone's own factors (`margins`: acceleration, jerk) again, its jerk rows
        linearized at the relaxed solution; that plan if feasible (`tight` back at the
        margins), else `relaxed` (`tight` at the limits in the zone).

        Why: a moving start can be infeasible at the margins merely because of where the
        first jerk pass is linearized. The v+a solution brakes at the last moment at full
        acceleration, far above any jerk-limited braking, and the tangent rows there are
        conservative by the gap (q = q*/4: 0.69 of J / sqrt(q)). Measured on the dwell
        layer's window from 958 mm/s at -1388 mm/s^2, 124 mm before a tangent corner
        passed at ~10 mm/s (`test_dwell_layer_window_braking_into_its_turnaround_plans`):
        its S-curve gets there from ~0.8 x the jerk limit on, the LP's jerk factor in the
        zone had to be >= 0.91-0.94 linearized at the v+a solution (acceleration factor
        1-0.98; infeasible at the margin 0.85), >= 0.78-0.80 at the relaxed solution.
        Kept at the limits, the zone planned at the rows' edge, where the quintic
        exceeded the limits by 1-18 % and every repair made the LP infeasible again (it
        failed)."""
        relaxed_factors = (tight.acc[:zone].copy(), tight.jerk[:zone].copy())
        tight.acc[:zone], tight.jerk[:zone] = margins
        try:
            return self.solve_grid(request, geo, tight, stop_idx, head, start_q=relaxed.q,
                                   passes=self.max_passes, start_envelope=True)
        except PlanningError:
            tight.acc[:zone], tight.jerk[:zone] = relaxed_factors
            return relaxed

    @property
    def _use_elastic(self) -> bool:
        """The elastic relaxation is on, and the solver an LP solver: OSQP's proximal QP
        pulls every variable towards its upper bound (`OsqpBackend`), a slack has none."""
        return self.elastic and self.solver != "osqp"

    def _start_zone(self, request: PlanRequest, geo: GridGeometry) -> int:
        """Nodes of the start zone, whose rows are relaxed first to the limits, then
        made elastic (`lp.elastic`), when the LP from a moving start is infeasible: those
        within ZONE_REACH braking distances of the start feed at the path limits (where
        the start state still shapes what the plan can do), at least START_ZONE_MIN."""
        A, J = path_limits(request.path, request.limits)
        reach = ZONE_REACH * braking_distance(float(request.start.v), A, J)
        k = int(np.searchsorted(geo.s, geo.s[0] + reach, side="right"))
        return int(min(max(k, START_ZONE_MIN), geo.n_nodes))

    def _caps(self, request: PlanRequest, geo: GridGeometry, tight: Tightening) -> np.ndarray:
        lim = request.limits
        vcap = np.sqrt(velocity_caps(geo, lim.vmax)) * tight.vel
        vcap = np.minimum(vcap, c1_knot_caps(request.path, geo.s, lim, request.dt))
        if request.feed_cap is not None:  # the repairs' tightening applies to it too
            vcap = np.minimum(vcap, request.feed_cap.at_nodes(geo.s) * self._repaired(tight))
        return vcap**2

    def _repaired(self, tight: Tightening) -> np.ndarray:
        """Per node, the repairs' tightening of the velocity factor below its initial
        margin (1 where no repair tightened it)."""
        return np.minimum(tight.vel / self.margins[0], 1.0)

    def _envelope(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                  stop_idx: np.ndarray, include_start: bool = True) -> np.ndarray:
        """Jerk-limited S-curve bounds on q after the start (unless not `include_start`),
        before a rest end and around interior stops (`lp.envelope`). Around a rest (a
        start at rest, a rest end, the stops) at the tangents there where they bound the
        motion (`lp.envelope.rest_envelope`: a C-dominated stroke of the winder started
        at X's 2000 mm/s^2 where its axes allow 5244); around a rest in a bend at the
        tangent's limits lowered by the curvature terms where that lifts the conservative
        envelope (`lp.envelope.lowered_rest_envelope`; not at a window's provisional end);
        from a moving start, into a moving end and elsewhere at `envelope_limits`."""
        A, J = envelope_limits(geo.d1, request.path.path_scale, request.limits)
        s = geo.s
        q_top = float(np.max(velocity_caps(geo, request.limits.vmax)))
        # one S-curve per prescribed state, with the tightest factors of its reach
        reach = braking_distance(float(np.sqrt(q_top)), A, J)

        def factors(centre: float) -> tuple[float, float]:
            near = np.abs(s - centre) <= reach
            return (self.envelope_jerk * J * float(np.min(tight.jerk[near])),
                    A * float(np.min(tight.acc[near])))

        def rest(centre: float, lowered: bool = True) -> np.ndarray:
            args = (s, centre, geo.d1, geo.d2, geo.d3, request.limits,
                    self.envelope_jerk * tight.jerk, tight.acc, q_top)
            local = rest_envelope(*args)
            if local is not None:
                return local
            conservative = reachable_q(np.abs(s - centre), 0.0, 0.0, *factors(centre))
            bound = lowered_rest_envelope(*args, conservative) if lowered else None
            return conservative if bound is None else bound

        a0 = request.start.a
        env = np.full(s.size, np.inf)
        if include_start and request.start.v <= REST and a0 == 0.0:
            env = rest(s[0])
        elif include_start:
            Jn, An = factors(s[0])
            if a0 < 0.0 and request.start.v > REST:
                # a braking start: an envelope that releases the braking more slowly than
                # a0^2 / v0 would reach rest (or near it) first, and the LP with it; the
                # state's own plan released faster (measured: the heuristic's brake at
                # -2764 mm/s^2 from 300 mm/s, the 0.6 J envelope forced a stall)
                Jn = max(Jn, a0 * a0 / request.start.v)
            env = reachable_q(s - s[0], request.start.v, a0, Jn, max(An, a0 + 1e-6 * abs(a0)))
        # the way into the end state (rest, or v_end with path acceleration 0) backwards
        if request.v_end > REST:
            env = np.minimum(env, reachable_q(s[-1] - s, request.v_end, 0.0,
                                              *factors(s[-1])))
        else:
            # a window's provisional end keeps the conservative envelope in a bend (with
            # the lowered bound there the windows braked later and their replans lost:
            # engine-lp cam-style-R50 +1.0 %, c-fourier-xc +0.7 %; stop 50)
            env = np.minimum(env, rest(s[-1], lowered=_at_path_end(request)))
        for i in stop_idx:
            env = np.minimum(env, rest(s[i]))
        return env

    def _rest_caps(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                   stop_idx: np.ndarray, room: np.ndarray) -> np.ndarray:
        """What the braking `room` of a moving start (`_brake_room`) may not exceed (q per
        node): nothing where the room's braking comes to rest within the window (it is
        a way down), else the S-curve bounds on q into the rests (the end if at rest, the
        stops) at the tangents on the way (`lp.envelope.local_rest_q`), never below the
        start's hardest braking at the limits along its tangent (`start_limits`).

        Why: a start accelerating hard 421 mm before the end (1087 mm/s, +3814 mm/s^2)
        cannot stop within the window at the room's jerk; the room then lifted q above
        the end's envelope up to the last node and the plan reached rest at -5400 mm/s^2
        (18x jmax). Capped by the end's envelope of `_envelope` (the worst tangent of the
        path: 19600 mm/s^3; only C moves at the stroke's end: 51300) the LP was infeasible
        and the elastic start gave 9x jmax at the start. Capped where the room's braking
        reaches rest anyway, a start 0.07 mm before its end failed its repairs."""
        s = geo.s
        caps = np.full(s.size, np.inf)
        if room[-1] <= 0.0:
            return caps
        centres = [*(() if request.v_end > 0.0 else (s[-1],)), *s[stop_idx]]
        for centre in centres:
            caps = np.minimum(caps, local_rest_q(s, centre, geo.d1, request.limits,
                                                 self.envelope_jerk * tight.jerk, tight.acc))
        st = request.start
        A, J = start_limits(geo, request.limits)
        return np.maximum(caps, braking_q(s - s[0], st.v, st.a, J, max(A, -st.a)))

    def _brake_room(self, request: PlanRequest, geo: GridGeometry,
                    tight: Tightening) -> np.ndarray:
        """The room a moving start needs above the LP's velocity caps (q per node, path
        units^2 / s^2): the feed of the jerk-limited braking from the start state at
        `brake_jerk` x the path jerk (`lp.envelope.braking_q`), no higher than the velocity
        limits themselves (factor 1, scaled by the repairs' tightening since: tight.vel /
        the velocity margin) and the request's feed cap.

        Why: the LP's caps are the limits times a margin (0.995), and a start state from
        another plan (the heuristic's cruise, a plan at the full limits) can lie between
        the two. From (v_cap, a = 0) the feed cannot fall to 0.995 v_cap within one node
        (~6 mm) with a bounded jerk, yet the start slope row holds a = 0 at node 0: the
        LP was infeasible (the cascade of issue 13: every window after a heuristic
        fallback on the dwell layer). Under this room the braking itself is a feasible
        way down (and cruising, where the limits allow it). Where the start is above the
        limits themselves (an override) the room is that braking uncapped and the check
        allows the excess (`_start_allowance`)."""
        st = request.start
        A, J = start_limits(geo, request.limits)
        room = braking_q(geo.s - geo.s[0], st.v, st.a, self.brake_jerk * J, max(A, -st.a))
        true = self._true_caps(request, geo)
        factor = self._repaired(tight)
        # a start above the limits keeps the braking's excess over them (the check allows
        # it, `_start_allowance`); elsewhere the room ends at the limits
        if st.v**2 > true[0] * (1.0 + 1e-9):
            return np.where(room > true, room, np.minimum(room, true * factor**2))
        return np.minimum(room, true * factor**2)

    def _start_allowance(self, request: PlanRequest, geo: GridGeometry,
                         tight: Tightening) -> np.ndarray | None:
        """For a start above the velocity limits (an override lowered them): the factor
        (>= 1, per node) by which the check lets the feed exceed them: the start's own
        excess v0 / v_cap, as far as a braking at half the room's jerk from the start
        would still be above the limits (the LP's room, `_brake_room`, ends sooner), and
        one node beyond; 1 elsewhere. None for a start within the limits. A plan from such
        a start is never judged worse than the start is, nor for longer than a braking
        slower than its own."""
        st = request.start
        if st.v <= REST:
            return None
        true = self._true_caps(request, geo)
        if st.v**2 <= true[0] * (1.0 + 1e-9):
            return None
        A, J = start_limits(geo, request.limits)
        slow = braking_q(geo.s - geo.s[0], st.v, st.a, 0.5 * self.brake_jerk * J,
                         max(A, -st.a))
        above = slow > true
        above[1:] |= above[:-1].copy()
        # (1 + 1e-6: the check evaluates the path at an interpolated u, `analytic_ratios`)
        return np.where(above, (1.0 + 1e-6) * st.v / np.sqrt(true[0]), 1.0)

    @staticmethod
    def _start_acc_allowance(request: PlanRequest, geo: GridGeometry) -> float | None:
        """For a moving start whose axis acceleration x_ss v0^2 + x_s a0 is above the
        limits (a state handed over by a plan at the full limits, or past an override): the
        factor (> 1) by which the check lets the first grid interval's acceleration exceed
        them, the start's own excess; None for a start within the limits. No plan from that
        state can do better at t = 0, and the excess was refused as the plan's own (the
        repairs went round on it: 1.5 % on tube-1450,
        `test_an_accelerating_start_before_a_turnaround_plans`)."""
        st = request.start
        if st.v <= REST:
            return None
        ratio = float(np.max(np.abs(geo.d2[0] * st.v**2 + geo.d1[0] * st.a)
                             / request.limits.amax))
        # (1 + 1e-6: the check evaluates the path at an interpolated u, `analytic_ratios`)
        return (1.0 + 1e-6) * ratio if ratio > 1.0 else None

    def _true_caps(self, request: PlanRequest, geo: GridGeometry) -> np.ndarray:
        """q caps at the nodes from the request's limits themselves (no margin), the C1
        knots and the feed cap."""
        lim = request.limits
        true = np.minimum(velocity_caps(geo, lim.vmax),
                          c1_knot_caps(request.path, geo.s, lim, request.dt) ** 2)
        if request.feed_cap is not None:
            true = np.minimum(true, request.feed_cap.at_nodes(geo.s) ** 2)
        return true

    def _pretighten(self, request: PlanRequest, geo: GridGeometry, tight: Tightening,
                    stop_idx: np.ndarray, first_free: int = 0) -> None:
        """Scale the jerk factor by `envelope_margin` where a start/stop envelope bounds
        q (and a few nodes around it): where the envelope's straight q (constant path
        acceleration) meets the velocity cap, the quintic reconstruction overshoots the
        nodal jerk by ~15 % (measured), which otherwise costs a repair round per window.
        Not after a moving start: there the committed state may need the full jerk (a
        tighter row at the first nodes made replans infeasible)."""
        if self.envelope_margin >= 1.0:
            return
        env = self._envelope(request, geo, tight, stop_idx,
                             include_start=request.start.v <= REST)
        zone = env < self._caps(request, geo, tight)
        if not np.any(zone):
            return
        grown = zone.copy()
        for off in range(1, self.zone_pad + 1):
            grown[off:] |= zone[:-off]
            grown[:-off] |= zone[off:]
        grown[:first_free] = False  # reused nodes keep the factors they were solved with
        tight.jerk[grown] *= self.envelope_margin

    def _relieve_start(self, request: PlanRequest, tight: Tightening) -> None:
        """After a moving start, the first `start_relief` nodes get the limits themselves
        (factors 1) for acceleration and jerk: the start state comes from a plan that met
        the limits, not the margins, and may need all of them to continue (a state braking
        at 0.99 amax cannot be followed under a 0.98 row)."""
        if request.start.v <= REST or self.start_relief <= 0:
            return
        k = self.start_relief
        tight.acc[:k] = 1.0
        tight.jerk[:k] = 1.0

    def _profile(self, request: PlanRequest, plan: GridPlan, a_start: float) -> FeedProfile:
        return profile_from_grid(plan.s, plan.q, a_start, 0.0)  # ends with acceleration 0

    def _repair_round(self, solve: Callable[..., GridPlan], before: Tightening,
                      plan: GridPlan, ratios: SampledRatios, profile: FeedProfile,
                      q_star_head: np.ndarray | None, reach: int
                      ) -> tuple[GridPlan, int]:
        """One repair round's jerk pass, linearized at the last plan (its nodes `plan.s`,
        its profile `profile`, whose check found `ratios`, on the profile's clock): first
        on the zones of `reach` nodes around the excesses with the other nodes held
        (`lp.local_repair`), each infeasible zone LOCAL_REPAIR_GROWTH x wider; then on the
        whole grid (at once if reach is 0). Returns the plan and the reach for the next
        round: the one that was feasible, 0 if none was (n-butterfly's zones were
        infeasible at 32 nodes and feasible at 128 round after round; on
        c-corners-bspline-2d none was, 10 LPs for nothing)."""
        node_times = profile.s_of_t.x - profile.s_of_t.x[0]
        while 0 < reach < plan.s.size:
            zone = repair_zone(ratios, node_times, reach)
            if zone.all():
                break
            try:
                return solve(before=before, start_q=plan.q, passes=1,
                             q_star_head=q_star_head, hold=~zone), reach
            except PlanningError:
                reach *= LOCAL_REPAIR_GROWTH
        return solve(before=before, start_q=plan.q, passes=1, q_star_head=q_star_head), 0

    @staticmethod
    def _tighten(tight: Tightening, ratios: SampledRatios, profile: FeedProfile,
                 s: np.ndarray, dt: float) -> None:
        """Scale the limits down around every time where one was exceeded."""
        t_nodes = profile.s_of_t.x - profile.s_of_t.x[0]
        for arr, t_at, factors, cut in ((ratios.vel, ratios.t_vel, tight.vel, VEL_CUT),
                                        (ratios.acc, ratios.t_acc, tight.acc, 0.97),
                                        (ratios.jerk, ratios.t_jerk, tight.jerk, 0.97)):
            bad = np.nonzero(arr > 1.0)[0]
            if bad.size == 0:
                continue
            node = np.clip(np.searchsorted(t_nodes, t_at[bad]) - 1, 0, s.size - 1)
            shrink = np.clip(cut / arr[bad], 0.6, cut)
            per_node = np.ones(s.size)
            for i, f in zip(node, shrink, strict=True):
                sl = slice(max(i - 2, 0), min(i + 4, s.size))
                per_node[sl] = np.minimum(per_node[sl], f)
            factors *= per_node

