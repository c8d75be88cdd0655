"""The heuristic planner: S-curves per planning segment with free junction states found by
a backward jerk-limited scan and a forward chain of rises (critical points), verified and
repaired, on several layouts of planning segments (the fastest verified plan wins).

1. Geometry on a grid of cells -> feed limit per cell (axis velocity, centripetal
   acceleration, geometric jerk, C1-knot cap, feed cap); cells grouped into planning
   segments by bands of that limit (`path_limits`), split where a segment's constant cap
   loses much time under the limit curve (`split`).
2. Per segment a cruise cap V and path acceleration / jerk budgets A, J that keep every
   axis term within its limit, and acceleration budgets for lower feeds (`levels`: the
   rises follow them).
3. Junction states (feed and path acceleration) from the scans, one motion per planning
   segment between them (`scan`); where that finds no chain, and as a layout of its own,
   the paper's junctions with path acceleration 0 (`zero_junctions`). Tight bends pass
   in valley motions above the caps (`valley`; a valley the chain cannot pass or the
   verification refuses is dropped, the round planned again). Steps 1-4 run per
   `Layout` (band ratio, budget shares); the fastest verified profile is returned.
4. Verification of axis velocity, acceleration and jerk at the budget and check points
   (`verify`), and by the checker's finite differences over the valleys and the cells the
   points do not resolve (`path_limits.rough_cells`); failing segments get their V, A, J
   lowered and steps 2-4 repeat. A profile that still fails raises PlanningError (never
   an unverified profile).
5. A start above the limits (override down, lower feed cap): first a brake (`brake`), then
   steps 1-4 from where it ends. A start above the feed limit but within the axis limits
   (inside a valley motion of the last plan, or of a wider layout's): steps 1-4 from it,
   the valley continued from the start (`valley.start_valley`), where no brake plans or
   where that is faster than the brake.
6. A replan that starts on the last plan and loses time against it: the last plan kept
   up to its next cruise state, steps 1-5 from there (`continuation`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile, PathState, PlanningError, PlanRequest, PlanResult
from lookahead.planning.heuristic.brake import (
    BRAKE_TARGETS,
    Brake,
    BrakeRefusedError,
    first_cells,
    phases_end,
    state_scale,
)
from lookahead.planning.heuristic.continuation import (
    LastPlan,
    prefix_within_limits,
    seam_state,
    seam_time,
    start_time,
    time_at_s,
)
from lookahead.planning.heuristic.levels import LEVEL_FRACTIONS, FeedLevels, level_budgets
from lookahead.planning.heuristic.path_limits import (
    BudgetShares,
    PathGrid,
    build_grid,
    choose_segments,
    feed_limit,
    rough_cells,
    segment_budgets,
)
from lookahead.planning.heuristic.profile_build import build_profile, concat_phases
from lookahead.planning.heuristic.scan import chain, neighbour_min
from lookahead.planning.heuristic.scurve import (
    Phases,
    SCurveSolver,
    SegmentInfeasibleError,
    reachable_feed,
)
from lookahead.planning.heuristic.split import split_by_loss
from lookahead.planning.heuristic.valley import find_valleys, raise_valley_caps
from lookahead.planning.heuristic.verify import (
    failing_segments,
    sampled_failing_runs,
    sampled_failing_segments,
)
from lookahead.planning.heuristic.zero_junctions import (
    first_caps,
    forward_pass,
    junction_caps,
    junction_feeds,
    zero_junction_parts,
)
from lookahead.planning.profile_ops import concatenate, slice_profile

#: repair step: factor on V, A, J of a segment that fails verification (0.85: 1-3 rounds on
#: the tubes, Fourier and random wandering paths of tests/heuristic_paths.py)
REPAIR_STEP = 0.85
#: repair rounds a further layout gets once one has a verified profile; each round's
#: profile that is no faster than that one ends the layout unverified (`_CannotWinError`:
#: repairs only slow a profile down). A compute bound: from a replan's moving start a
#: layout that does not suit it failed all 12 rounds on the tubes. 2 since stop 50, side
#: by side with 1 on the 64 non-long paths (bench/results/corpus_heuristic_rounds2_{before,
#: after}.json): n-heart -4.8 % (its wide layout verifies in round 2 and wins), engine
#: cam-style-R100 -0.5 %, nothing slower; compute whole job 39.7 -> 38.5 s, engine
#: 160.7 -> 161.3 s. Without the check in every round, 2 rounds cost the engine +7.7 %
#: (corpus_heuristic_other_rounds_{1,2}.json)
OTHER_LAYOUT_ROUNDS = 2
#: repair rounds per layout in the first pass over the layouts (a compute bound: from a
#: cold replan braking on the butterfly the coarse layout failed all 12 rounds, 1.55 s,
#: while the wide one verified in 1; the winning layout needed 1 round in every case
#: measured (see OTHER_LAYOUT_ROUNDS), so the full rounds only run where no layout
#: verified within these)
FIRST_PASS_ROUNDS = 2
#: a layout planned after another one has a verified profile does not merge leading
#: segments for the zero-junction fallback (a compute bound: on the B-spline corners a
#: replan braking at a = -883 merged 180 segments of the wide layout, 0.67 s, to fail; the
#: merged zero-junction plans won no layout on the fast corpus's replans)
MERGE_IN_OTHER_LAYOUTS = False
#: band ratio of the layouts replanned where no layout plans from a moving start
#: (`HeuristicPlanner._rescue_plan`; 1.1: both refused replan-continuity states of the fast
#: corpus planned, with the coarse and the wide shares; only runs where the plan failed)
RESCUE_BAND_RATIO = 1.1
#: free-junction chains tried per round while leading segments are merged for a start
#: state that cannot stop in the first one (a compute bound: on a polar dome a replan
#: merged 60 times, each chain failing, 1.2 s; the merges are for the zero-junction plan)
FREE_TRIES = 2


#: chains tried with valleys per round, each without the valley where the last one gave
#: up (then one without any; a compute bound: 2 planned the fast corpus as 4 did, 1 lost
#: the B-spline corners' valleys, 5.903 s against 5.727)
VALLEY_CHAINS = 2
#: replans of a round whose only failing segments were at valleys, without those valleys
#: (not counted as repair rounds: a layout planned with one round after another verified
#: lost to a refused valley; random XY path, engine: 1.042 -> 1.048 of the LP)
VALLEY_RETRIES = 2


class _RoundsExhaustedError(PlanningError):
    """A layout's profile still failed verification after its last repair round."""


class _CannotWinError(PlanningError):
    """A layout's last round planned a profile no faster than the best verified one of
    another layout: verified or not, it would not be chosen (so it is not verified)."""


class _FirstPassFailedError(PlanningError):
    """No layout verified in `_plan_phases`'s first pass, which was asked to stop there;
    `exhausted`: the layouts (indices, in order) that ran out of rounds, which the second
    pass would replan with all of them."""

    def __init__(self, problem: str, exhausted: list[int]) -> None:
        super().__init__(problem)
        self.exhausted = exhausted


@dataclass(frozen=True)
class Layout:
    """One way to cut the path into planning segments: the band ratio of the feed limit
    that starts a new segment and the shares of the limits the budgets use."""

    band_ratio: float
    shares: BudgetShares
    #: where the free-junction chain finds no motion, plan the paper's junctions (path
    #: acceleration 0) instead; off for fine bands, where hundreds of zero-acceleration
    #: junctions make the jerk chatter (Fourier path: 55 sign changes per second, 120 of
    #: them within 5 ms of the last) and the layout then simply fails
    zero_fallback: bool = True
    #: skip the layout when it cuts the window into more planning segments than this
    #: (None: no limit). A compute bound: the fine layout won only on paths of few long
    #: segments (tubes: 28-61 segments for a whole circuit) and cost 2-3x the coarse one
    #: on wiggly paths (300-1100 segments) where it lost anyway
    max_segments: int | None = None
    #: False: the paper's junctions (path acceleration 0) only
    free_junctions: bool = True
    #: split segments whose constant cap loses time under the limit curve (`split`)
    split: SplitRule | None = None
    #: acceleration budgets per feed level in the rises (`levels`); None: one per segment
    levels: tuple[float, ...] | None = None


@dataclass(frozen=True)
class SplitRule:
    """`split.split_by_loss` parameters: a segment is split where its cap loses more than
    `rel_loss` of its time at the limit and more than `abs_dt` sample times, into runs
    below / above `step` times its cap."""

    rel_loss: float = 0.02
    abs_dt: float = 1.0
    step: float = 1.05


#: the loss split of the coarse layouts: a segment is split where its cap loses > 2 % of
#: its time at the limit and > 50 samples (a long stroke whose first cells sit 20 % lower:
#: Fourier path 15.5 -> 12.8 s with the wider shares); 1 sample cut 2-3x as many short
#: segments and lost 1-10 % on the circle, the near-cusp cycloid and the B-spline corners
#: (more junctions); 20 samples won 0.2 % more on the Fourier path but made 12 jerk sign
#: changes within 5 ms on the chattering test's Fourier path (50: 5; the test allows 8)
COARSE_SPLIT = SplitRule(rel_loss=0.02, abs_dt=50.0, step=1.05)

#: layouts planned in turn, the fastest verified profile wins. All free-junction layouts
#: use feed-level acceleration budgets (`levels`; with the scan's forward rises after a
#: restart, the coarse layout: circle -8 %, B-spline corners -15 %, near-cusp cycloid
#: -21 %). The paper's coarse bands with the default shares win where the path turns
#: sharply (corners, cycloids: the wider shares lose 10-50 % there); the same bands with
#: more of amax / jmax for the geometry win where the limit curve is high and wavy
#: (circle under per-axis limits -3.4 %, ellipse -4.6 %, flower -8 %, butterfly -3.3 %,
#: polar dome -3.8 %); fine bands with most of amax / jmax follow the curve on the tubes (2-10 %
#: faster than coarse, within 0-3 % of the LP; skipped above 200 segments, where they
#: cost 2-3x and lost). The paper's own zero-acceleration junctions stay the coarse
#: layouts' fallback but no longer a layout of their own: on the 56 non-long corpus paths
#: they won none (ties on 5), at 10-40 % of the compute. Measured on
#: tests/heuristic_paths.py and the corpus (fast set, and all but the long paths).
COARSE = Layout(1.25, BudgetShares(), split=COARSE_SPLIT, levels=LEVEL_FRACTIONS)
COARSE_WIDE = Layout(1.25, BudgetShares(centripetal=0.75, jerk_geometric=0.4),
                     split=COARSE_SPLIT, levels=LEVEL_FRACTIONS)
FINE = Layout(1.05, BudgetShares(centripetal=0.9, jerk_geometric=0.5), zero_fallback=False,
              max_segments=200, levels=LEVEL_FRACTIONS)
#: the paper's heuristic: zero-acceleration junctions only (for comparisons)
ZERO_JUNCTIONS = Layout(1.25, BudgetShares(), free_junctions=False)
LAYOUTS = (COARSE, COARSE_WIDE, FINE)


#: a replan that starts on the last plan is joined onto it (`HeuristicPlanner._continued`)
#: only where the fresh plan reaches the last plan's next cruise state this much later
#: than the last plan does (relative; the joined plan costs a second plan) and the joined
#: plan takes this much less time over the window than the fresh one. Trades time
#: against smoothness: the last plan's feed up to the seam may lie above the caps of the
#: layout the rest is planned on, which then brakes at once (at 1e-3, a joined plan of
#: the 3-stroke X/C job of tests/test_stream_ahead.py cruised at 1262 mm/s into a dip to
#: 1219 mm/s and back to 1241, where the fresh plan cruised at 1241, for a window less
#: than 0.5 % shorter). Joined plans that won on corpus paths gained 0.05 %
#: (w-cone-R80to40) to 5.8 % (c-rand4) of their window; at 0.5 % the sub-percent ones
#: stay fresh
CONTINUE_GAIN = 0.005


class HeuristicPlanner:
    """Heuristic planner: free-junction S-curve chain, verification + repair.

    margin: fraction of each axis limit planned to (the checker judges at 1.0).
    band_ratio, shares: one layout of planning segments (default: `LAYOUTS`, all planned,
    the fastest verified profile wins; the one that won the last plan is tried first, as
    a replan continues it); layouts: several.
    max_cell: longest geometry cell (path units; default path length / 2000).
    repair_rounds: verification/repair passes before giving up.
    free_junctions: False plans the paper's junctions (path acceleration 0) only.
    valleys: pass tight bends with valley motions (`valley`); False cruises at every bend's
    caps (the planner before stop 25). A valley is a discrete choice at its checks' edges:
    the points' last bits can flip it (a stroke at C = 190,000 deg against C = 0: 23 valley
    segments against 22, 0.22 % winding time).
    sampled_verify: after the grid-point check, also the checker's finite differences on
    the profile sampled at four phases of dt (`verify.sampled_failing_segments`); a
    profile leaves the planner only if both pass. Off by default: it costs 5-10x the plan
    (the arc-length inversion of 4 samples per dt); since the velocity share
    (`BudgetShares.velocity`) the checker found nothing the grid check had passed on
    tests/heuristic_paths.py and the corpus's fast set, and on a pchip tube its four
    phases cost 8 % winding time for differences the single-phase checker accepted.
    continue_last: a replan that starts on the last plan may keep it up to its next cruise
    state (`continuation`): the engine's planner of a job's windows. False for planners
    whose requests do not continue one another (stops, shortest-stop searches, the LP's
    transients, fallbacks).
    brake_within_limits: when the plan from a moving start fails, try the brake fallback
    (brake, then plan the rest) also if the start state is within the limits. False for a
    shortest-stop search (`stream.plans.shortest_stop`): its too-short trials then fail in
    ~2 ms instead of ~20.
    """

    name = "heuristic"

    def __init__(self, margin: float = 0.98, band_ratio: float | None = None,
                 max_cell: float | None = None,
                 shares: BudgetShares | None = None, repair_rounds: int = 12,
                 brake_within_limits: bool = True, free_junctions: bool = True,
                 layouts: tuple[Layout, ...] | None = None,
                 sampled_verify: bool = False, valleys: bool = True,
                 continue_last: bool = True) -> None:
        self.brake_within_limits = brake_within_limits
        self.continue_last = continue_last
        self.valleys = valleys
        self.sampled_verify = sampled_verify
        self.margin = margin
        if layouts is None:
            layouts = LAYOUTS if band_ratio is None and shares is None else (
                Layout(band_ratio or 1.25, shares or BudgetShares()),)
        self.layouts = layouts
        self.max_cell = max_cell
        self.shares = shares or BudgetShares()
        self.repair_rounds = repair_rounds
        self.free_junctions = free_junctions
        self._solver = SCurveSolver()
        self._last_layout = 0
        self._fixed: np.ndarray | None = None  # the last chain's valley segments
        self._last: LastPlan | None = None  # the last plan returned (`continuation`)
        self._brake = Brake(self.shares, margin, self._solver)

    # --- public ---------------------------------------------------------------------
    def plan(self, request: PlanRequest) -> PlanResult:
        """The fastest verified profile for the request: planned afresh, or (a replan
        that starts on the last plan and loses time against it) the last plan kept up
        to its next cruise state and planned afresh from there (`continuation`)."""
        t_start = time.perf_counter()
        try:
            fresh = self._plan_fresh(request)
        except PlanningError:
            # a replan on the last plan that no fresh plan verifies may still go on
            # from the last plan's next cruise state
            result = self._continued(request, None)
            if result is None:
                self._last = None
                raise
        else:
            result = self._continued(request, fresh) or fresh
        self._last = LastPlan(request, result.profile)
        return replace(result, compute_s=time.perf_counter() - t_start)

    def forget(self) -> None:
        """Drop the last plan (the next request is planned without continuing it)."""
        self._last = None

    def _continued(self, request: PlanRequest, fresh: PlanResult | None
                   ) -> PlanResult | None:
        """The last plan up to its seam (`continuation.seam_time`) then a fresh plan from
        there, where the fresh plan reaches the seam more than CONTINUE_GAIN later than
        the last plan does and the joined plan ends CONTINUE_GAIN sooner (`fresh` None: no
        fresh plan verified; then wherever the joined one does); else None."""
        last = self._last
        if not self.continue_last:
            return None
        t0 = start_time(last, request)
        if t0 is None:
            return None
        t1 = seam_time(last.profile, t0, request.dt)
        if t1 is None:
            return None
        seam = seam_state(last.profile, t1)
        if not seam.s < request.s_end or (fresh is not None and not time_at_s(
                fresh.profile, seam.s) > (t1 - t0) * (1.0 + CONTINUE_GAIN)):
            return None
        prefix = slice_profile(last.profile, t0, t1)
        if not prefix_within_limits(request, prefix, self.shares, self.max_cell):
            return None
        # from the seam, a cruise state, only the layouts' first pass: a seam that needs
        # brakes, rescues or full repair rounds is no better than the fresh plan (on the
        # pocketing program a failing second pass from a seam took 2.3 s)
        rest_request = replace(request, start=seam)
        limits = request.limits.scaled(self.margin)
        grid, vlim = self._grid(rest_request, seam, limits)
        if seam.v > self._start_limit(rest_request, grid, vlim, limits):
            return None  # (a cruise of the last plan above every layout's feed limit)
        try:
            phases, info = self._plan_phases(rest_request, grid, vlim, limits,
                                             second_pass=False)
        except PlanningError:
            return None
        rest = build_profile(phases)
        if fresh is not None and not (prefix.duration + rest.duration
                                      < (1.0 - CONTINUE_GAIN) * fresh.profile.duration):
            return None
        return PlanResult(concatenate([prefix, rest]), self.name, 0.0,
                          {**info, "continued_s": seam.s - request.start.s})

    def _plan_fresh(self, request: PlanRequest) -> PlanResult:
        """A plan for the request that does not look at the last plan."""
        t_start = time.perf_counter()
        start = request.start
        s_end = float(request.s_end)
        if not s_end > start.s:
            if s_end == start.s and start.v == 0 and start.a == 0:
                return self._result(_rest_profile(start.s, request.dt), t_start, {"segments": 0})
            raise PlanningError(f"s_end ({s_end}) must lie after start.s ({start.s})")
        if start.v < 0 or request.v_end < 0:
            raise PlanningError("feeds must be >= 0")
        limits = request.limits.scaled(self.margin)
        grid, vlim = self._grid(request, start, limits)
        first_problem = ""
        if not request.start.v > vlim[0] / self.margin:
            # from a moving start that may brake, the rescue (finer bands, first-pass
            # rounds) runs before the layouts' full repair rounds: on the fast corpus's
            # 700 replan-continuity states the full rounds planned none (2 tried, 2 s
            # each), the rescue planned one of them in 0.5 s
            defer = not (start.v == 0 and start.a == 0) and not (
                not self.brake_within_limits and state_scale(request, grid) <= 1.0)
            try:
                phases, core = self._plan_phases(request, grid, vlim, limits,
                                                 second_pass=not defer)
                return self._result(build_profile(phases), t_start, core)
            except PlanningError as exc:
                if not defer:
                    raise
                first_problem = str(exc)  # perhaps the start acceleration is too high
                rescued = self._rescue_plan(request, grid, limits)
                if rescued is not None:
                    return self._result(build_profile(rescued[0]), t_start, rescued[1])
                exhausted = exc.exhausted if isinstance(exc, _FirstPassFailedError) else []
                try:
                    phases, core = self._second_pass(request, grid, vlim, limits,
                                                     exhausted, first_problem)
                    return self._result(build_profile(phases), t_start, core)
                except PlanningError as exc2:
                    first_problem = str(exc2)
        # brake to the limits first; if the rest cannot follow from there (the window is
        # too short for that feed), brake to a lower feed. First pass: each target's rest
        # gets the layouts' first-pass rounds only; the full rounds (`_plan_phases`'s
        # second pass) run, target by target, only where no target planned in the first
        # pass (the same attempts as planning each target fully in turn, reordered: from
        # a butterfly replan the full rounds failed on the first two targets, 14 s, while
        # the third target's rest verified in its first round). A target whose brake
        # ends in the state of an earlier target's brake is not planned again.
        problem = ""
        refused = False  # `problem` is the brake's own refusal (BrakeRefusedError)
        retry: list[tuple[float, float, Phases, PlanRequest, PathGrid, np.ndarray,
                          list[int]]] = []
        tried: set[tuple[float, float, float]] = set()
        for fraction in BRAKE_TARGETS:
            try:
                brake, g = self._brake.brake(request, grid, vlim, limits, fraction)
            except PlanningError as exc:
                problem, refused = str(exc), isinstance(exc, BrakeRefusedError)
                break
            end = phases_end(brake)
            # a corner beyond the window's end is the next window's: not this brake's
            corner = _first_corner(grid, request.start.s, min(end.s, s_end))
            if corner is not None:
                # the machine must be at rest at a corner: stop there instead, and go on
                # from rest (c-corners-bspline-2d replan: every brake ran 48-50 mm through
                # a corner 7 mm ahead)
                if (corner, 0.0, 0.0) in tried:
                    continue
                try:
                    brake, g = self._brake.stop_at(request, grid, limits, corner)
                except PlanningError as exc:
                    problem, refused = str(exc), False
                    tried.add((corner, 0.0, 0.0))
                    continue
                end, fraction = PathState(corner, 0.0, 0.0), 0.0  # brake_target 0: a stop
            if not end.s < s_end:
                break
            if (end.s, end.v, end.a) in tried:
                continue  # the same rest as a target that failed
            tried.add((end.s, end.v, end.a))
            rest = replace(request, start=end)
            rest_grid, rest_vlim = self._grid(request, end, limits)
            try:
                phases, core = self._plan_phases(rest, rest_grid, rest_vlim, limits,
                                                 second_pass=False)
            except _FirstPassFailedError as exc:
                problem, refused = str(exc), False
                if exc.exhausted:
                    retry.append((fraction, g, brake, rest, rest_grid, rest_vlim,
                                  exc.exhausted))
                continue
            except PlanningError as exc:
                problem, refused = str(exc), False
                continue
            info = {"brake_scale": g, "brake_target": fraction, **core}
            return self._result(build_profile(self._faster_going_on(
                request, grid, vlim, limits, concat_phases([brake, phases]), info, tried)),
                t_start, info)
        for fraction, g, brake, rest, rest_grid, rest_vlim, exhausted in retry:
            try:
                phases, core = self._second_pass(rest, rest_grid, rest_vlim, limits,
                                                 exhausted)
            except PlanningError as exc:
                problem, refused = str(exc), False
                continue
            info = {"brake_scale": g, "brake_target": fraction, **core}
            return self._result(build_profile(self._faster_going_on(
                request, grid, vlim, limits, concat_phases([brake, phases]), info, tried)),
                t_start, info)
        if request.start.v > vlim[0] / self.margin and \
                self._may_go_on(request, grid, vlim, limits):
            # a wider layout's plan, or a valley motion from the start, may go on from it
            try:
                phases, core = self._plan_phases(request, grid, vlim, limits)
                return self._result(build_profile(phases), t_start, core)
            except PlanningError as exc:
                problem = f"{problem} {exc}"
        if refused:  # the brake's own reason says it all
            raise PlanningError(problem)
        raise PlanningError("the start state cannot slow down to the limits within the "
                            f"window [{start.s}, {s_end}]: {first_problem} {problem}")

    # --- steps ------------------------------------------------------------------------
    def _grid(self, request: PlanRequest, start: PathState,
              limits: AxisLimits) -> tuple[PathGrid, np.ndarray]:
        grid = build_grid(request.path, start.s, request.s_end, request.dt, limits,
                          self.shares, request.feed_cap, self.max_cell, (start.v, start.a))
        return grid, feed_limit(grid, limits, self.shares, request.feed_cap)

    def _plan_phases(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                     limits: AxisLimits, second_pass: bool = True) -> tuple[Phases, dict]:
        """The fastest verified profile over the layouts (PlanningError if none is).
        First pass: the layout that won last first (a replan continues its plan), each
        layout FIRST_PASS_ROUNDS repair rounds, once one has a verified profile the others
        only OTHER_LAYOUT_ROUNDS; second pass (none verified; `second_pass` False: raise
        `_FirstPassFailedError` naming them instead): the layouts that ran out of rounds
        get all of them, in the same order (`_second_pass`)."""
        order = sorted(range(len(self.layouts)), key=lambda i: i != self._last_layout)
        best, problem, exhausted = None, "", []
        for i in order:
            rounds = min(self.repair_rounds,
                         FIRST_PASS_ROUNDS if best is None else OTHER_LAYOUT_ROUNDS)
            try:
                phases, info = self._layout_plan(request, grid, vlim, limits, i, rounds,
                                                 best is None or MERGE_IN_OTHER_LAYOUTS,
                                                 None if best is None else best[2])
            except _CannotWinError:
                continue
            except PlanningError as exc:
                problem = str(exc)
                if isinstance(exc, _RoundsExhaustedError) and rounds < self.repair_rounds:
                    exhausted.append(i)
                continue
            duration = float(np.sum(phases.duration))
            if best is None or duration < best[2]:
                best = (phases, {**info, "layout": i}, duration)
        if best is None:
            if not second_pass:
                raise _FirstPassFailedError(problem, exhausted)
            return self._second_pass(request, grid, vlim, limits, exhausted, problem)
        self._last_layout = best[1]["layout"]
        return best[0], best[1]

    def _second_pass(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                     limits: AxisLimits, exhausted: list[int], problem: str = ""
                     ) -> tuple[Phases, dict]:
        """The first of the `exhausted` layouts (indices, in order) that verifies with
        all repair rounds (PlanningError if none does)."""
        for i in exhausted:
            try:
                phases, info = self._layout_plan(request, grid, vlim, limits, i,
                                                 self.repair_rounds, True)
            except PlanningError as exc:
                problem = str(exc)
                continue
            # the layouts after it already failed more rounds than they would now get
            self._last_layout = i
            return phases, {**info, "layout": i}
        raise PlanningError(problem)

    def _faster_going_on(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                         limits: AxisLimits, braked: Phases, info: dict,
                         tried: set[tuple[float, float, float]]) -> Phases:
        """`braked` (a brake from a start above the feed limit, then the rest), or the
        plan that goes on from the start without a brake where `_may_go_on` allows one,
        verifies and takes less time over the same window (`info` updated in place: then
        the plan's own, with `went_on` and the beaten brake's `beaten_brake_target`).

        A start above the default shares' limit is mostly a state of the last plan
        made under wider shares or inside a valley motion: its brake to a fraction of
        the limit then crawls (cam-style-R100-a30-L600's replans from 1167 mm/s braking
        at 1000 mm/s^2, 4 s at 144 mm/s after the brake: 6.10 s where the whole-job plan
        takes 2.60 s over the same stretch); a plain plan from such a state can still
        lose to the brake elsewhere (on a wavy path the engine's replans took 3 % longer
        planned directly), so the two are compared, not ordered. `tried`: the brakes'
        end states whose rests were planned (a brake target at or above the start feed
        ends at the start itself, whose plan then failed already; a start below the feed
        limit was planned directly first, and failed)."""
        st = request.start
        if (st.s, st.v, st.a) in tried or not st.v > vlim[0] / self.margin or \
                not self._may_go_on(request, grid, vlim, limits):
            return braked
        try:
            phases, core = self._plan_phases(request, grid, vlim, limits, second_pass=False)
        except PlanningError:
            return braked
        if not float(np.sum(phases.duration)) < float(np.sum(braked.duration)):
            return braked
        beaten = info.get("brake_target")
        info.clear()
        info.update({**core, "went_on": True, "beaten_brake_target": beaten})
        return phases

    def _may_go_on(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                   limits: AxisLimits) -> bool:
        """Whether a start above the window's feed limit at the start (the default
        shares') is planned directly where no brake planned it: below the most
        permissive layout's feed limit (`_start_limit`), or within the axis velocity and
        acceleration limits (`brake.state_scale` <= 1), as inside a valley motion of the
        last plan, above the caps: the plan then continues it (`valley.start_valley`;
        polar dome, from inside its first valley: v = 82-108 mm/s against feed limits
        of 52-86 there, decelerating at up to 600 mm/s^2; every brake failed its check
        or found no scaling that admits the start)."""
        if state_scale(request, grid) <= 1.0:
            return True
        return not request.start.v > self._start_limit(request, grid, vlim,
                                                       limits) / self.margin

    def _start_limit(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                     limits: AxisLimits) -> float:
        """The feed limit at the start under the most permissive layout's shares: a
        replan starts on the last plan, which a layout with wider shares than the
        planner's own may have made (n-circle-R30: 205 mm/s under the wide shares, above
        the default shares' limit; taken for a start above the limits, its brake failed).
        Such a start is planned directly where no brake plans it (planned directly first,
        the engine's keep-distance replans on a wavy path took 3 % longer)."""
        head = first_cells(grid, 1)
        return max([float(vlim[0])] + [float(feed_limit(head, limits, L.shares,
                                                         request.feed_cap)[0])
                                       for L in self.layouts if L.shares != self.shares])

    def _rescue_plan(self, request: PlanRequest, grid: PathGrid, limits: AxisLimits
                     ) -> tuple[Phases, dict] | None:
        """From a moving start no layout planned: the layouts again with the finer bands
        RESCUE_BAND_RATIO (no segment-count bound), the fastest verified profile, or None.
        A start on the last plan's own brake can lie a hair above this window's budgets,
        which other cells and segments give (B-spline corners, butterfly: v ~ 60-100
        mm/s braking at 400-500 mm/s^2 towards a corner; refused by every layout); finer
        bands give segments caps and budgets closer to the local limit curve."""
        best = None
        for layout in self.layouts:
            if not layout.band_ratio > RESCUE_BAND_RATIO or not layout.free_junctions:
                continue
            fine = replace(layout, band_ratio=RESCUE_BAND_RATIO, max_segments=None)
            lim = feed_limit(grid, limits, fine.shares, request.feed_cap)
            try:
                phases, info = self._plan_layout(request, grid, lim, limits, fine,
                                                 FIRST_PASS_ROUNDS,
                                                 beat=None if best is None else best[2])
            except PlanningError:
                continue
            duration = float(np.sum(phases.duration))
            if best is None or duration < best[2]:
                best = (phases, {**info, "rescue": True}, duration)
        return None if best is None else best[:2]

    def _layout_plan(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                     limits: AxisLimits, i: int, rounds: int, merge: bool,
                     beat: float | None = None) -> tuple[Phases, dict]:
        """`_plan_layout` for layout i, on the feed limit of its shares."""
        layout = self.layouts[i]
        lim = vlim if layout.shares == self.shares else feed_limit(
            grid, limits, layout.shares, request.feed_cap)
        return self._plan_layout(request, grid, lim, limits, layout, rounds, merge, beat)

    def _plan_layout(self, request: PlanRequest, grid: PathGrid, vlim: np.ndarray,
                     limits: AxisLimits, layout: Layout, rounds: int,
                     merge: bool = True, beat: float | None = None) -> tuple[Phases, dict]:
        """Segments, S-curves, verification and repair from a start within the limits
        (`merge`: see `_profile_phases`). `beat` (s): the duration of the best verified
        profile so far; a round's profile that does not beat it raises `_CannotWinError`
        unverified (verification costs as much as a plan on short windows, the caller
        keeps only a faster profile, and a repair round only slows a profile down)."""
        shares = layout.shares
        starts = choose_segments(grid, vlim, layout.band_ratio)
        if layout.split is not None:
            rule = layout.split
            starts = split_by_loss(grid.edges, vlim, starts, rule.rel_loss,
                                   rule.abs_dt * request.dt, rule.step)
        if layout.max_segments is not None and starts.size - 1 > layout.max_segments:
            raise PlanningError(f"heuristic: layout of {starts.size - 1} segments skipped")
        factor = np.ones(starts.size - 1)
        rough = rough_cells(grid, request.limits, vlim)
        info: dict = {"rounds": 0, "verified": False, "zero_junction_rounds": 0}
        phases = None
        ban = np.zeros(starts.size - 1, dtype=bool)  # no valley touches these segments
        round_, retries = 0, 0
        while round_ < rounds:
            phases, new_starts, factor, free = self._profile_phases(
                request, grid, starts, factor, vlim, limits, shares, layout.zero_fallback,
                layout.free_junctions, layout.levels, merge, ban, self.valleys)
            if new_starts.size != starts.size:
                ban = np.zeros(new_starts.size - 1, dtype=bool)
            starts = new_starts
            fixed = self._fixed if free else None
            info["zero_junction_rounds"] += int(not free)
            if beat is not None and not float(np.sum(phases.duration)) < beat:
                raise _CannotWinError("heuristic: layout no faster than the best one")
            profile = build_profile(phases)
            failing = failing_segments(profile, grid, starts, request.limits,
                                       request.path, request.dt)
            if not failing.any() and self.sampled_verify:
                failing = sampled_failing_segments(request.path, profile, grid, starts,
                                                   request.limits, request.dt)
                info["sampled_repairs"] = info.get("sampled_repairs", 0) + int(failing.any())
            elif not failing.any():
                # the finite differences over valleys and rough cells, which the grid
                # points may pass between their peaks
                runs = np.logical_or.reduceat(rough, starts[:-1])
                if fixed is not None and fixed.size == failing.size:
                    runs |= fixed
                failing = sampled_failing_runs(request.path, profile, grid, starts, runs,
                                               request.limits, request.dt)
            info["rounds"] = round_ + 1
            if not failing.any():
                info["verified"] = True
                if fixed is not None:
                    info["valley_segments"] = int(np.count_nonzero(fixed))
                break
            if fixed is not None and fixed.size == failing.size:
                # a failing valley, or a segment next to one: the next round plans these
                # without valleys (and without lowering their budgets for it)
                near = fixed.copy()
                near[1:] |= fixed[:-1]
                near[:-1] |= fixed[1:]
                hit = failing & near
                ban |= _spans_of(fixed, hit)
                failing = failing & ~hit
                if hit.any() and not failing.any() and retries < VALLEY_RETRIES:
                    retries += 1  # only valleys failed: this round again without them
                    continue
            factor = np.where(failing, factor * REPAIR_STEP, factor)
            round_ += 1
        info["segments"] = int(starts.size - 1)
        info["cells"] = grid.ncells
        if not info["verified"]:
            raise _RoundsExhaustedError(f"heuristic: no profile within the limits after "
                                        f"{info['rounds']} repair rounds")
        return phases, info

    def _profile_phases(self, request: PlanRequest, grid: PathGrid, starts: np.ndarray,
                        factor: np.ndarray, vlim: np.ndarray, limits: AxisLimits,
                        shares: BudgetShares, zero_fallback: bool = True,
                        free: bool = True,
                        levels: tuple[float, ...] | None = None, merge: bool = True,
                        ban: np.ndarray | None = None, valleys: bool = False
                        ) -> tuple[Phases, np.ndarray, np.ndarray, bool]:
        """The phases of one round: the free-junction chain, else zero junctions. If the
        start state cannot reach a valid end state within the first segment, its cruise
        cap is first lowered to the start feed (which raises its acceleration and jerk
        budgets; only over the grid's leading cells where it has them, cut off as a segment
        of its own), then leading segments are merged (if `merge`; else PlanningError)."""
        lowered = False
        lead_cut = False
        v_cap = None
        tries = 0
        while True:
            b = segment_budgets(grid, starts, vlim, limits, shares, factor, v_cap)
            if self.free_junctions and free and tries < FREE_TRIES:
                tries += 1
                lv = None
                if levels is not None:
                    b, lv = level_budgets(grid, starts, vlim, limits, shares, b, factor,
                                          v_cap, levels)
                parts = self._free_parts(request, grid, starts, b, lv,
                                         (vlim, limits, shares, ban) if valleys else None)
                if parts is not None:
                    return concat_phases(parts), starts, factor, True
                if not zero_fallback:
                    raise PlanningError("heuristic: no free-junction chain for this layout")
            try:
                parts = zero_junction_parts(self._solver, request, grid, starts, b,
                                            self.margin)
                return concat_phases(parts), starts, factor, False
            except SegmentInfeasibleError:
                if not lowered and request.start.v > 0:
                    lowered = True
                    n_lead = grid.lead_cells
                    if n_lead and not lead_cut and starts[1] > n_lead:
                        lead_cut = True
                        starts = np.insert(starts, 1, n_lead)
                        factor = np.insert(factor, 0, factor[0])
                    v_cap = np.full(starts.size - 1, np.inf)
                    v_cap[0] = request.start.v
                elif not merge:
                    raise PlanningError("heuristic: the start state cannot stop in the "
                                        "first segment (no merges in this layout)") from None
                elif starts.size <= 2:
                    raise PlanningError("the start state cannot stop within the window "
                                        f"[{request.start.s}, {request.s_end}]") from None
                else:
                    lowered = False
                    starts = np.delete(starts, 1)
                    factor = np.delete(factor, 1)
                    v_cap = np.full(starts.size - 1, np.inf)

    def _free_parts(self, request: PlanRequest, grid: PathGrid, starts: np.ndarray,
                    b, levels: FeedLevels | None = None, valley_args: tuple | None = None
                    ) -> list[Phases] | None:
        """The free-junction chain's phases per segment, or None. `valley_args` (vlim,
        limits, shares; with levels): tight bends passed by valley motions (`valley`)."""
        self._fixed = None
        if valley_args is not None and levels is not None:
            vlim, limits, shares, ban = valley_args
            cap = junction_caps(request, grid, starts, b)
            hard = grid.c1_cap
            if request.feed_cap is not None:
                hard = np.minimum(hard, request.feed_cap.at(grid.s[:, 1]))
            st = request.start
            valleys = find_valleys(grid, starts, b, levels, vlim, cap, limits, shares,
                                   neighbour_min(b.J), ban, hard, (st.v, st.a))
            for _ in range(VALLEY_CHAINS):
                if not valleys:
                    break
                broken: list[int] = []
                got = self._chain(request, grid, starts, b, levels, valleys, broken)
                if got is not None:
                    self._fixed = got[1].get("fixed")
                    return got[0]
                # no chain through the valleys: again without the one where it gave up
                # (the first ending at or after that segment), else without any
                k = broken[0] if broken else -1
                drop = next((i for i, vy in enumerate(valleys) if vy.k1 + 1 >= k), None)
                if k < 0 or drop is None:
                    break
                valleys = valleys[:drop] + valleys[drop + 1:]
        got = self._chain(request, grid, starts, b, levels, None)
        return None if got is None else got[0]

    def _chain(self, request: PlanRequest, grid: PathGrid, starts: np.ndarray, b,
               levels: FeedLevels | None, valleys: list | None,
               broken: list | None = None):
        """`scan.chain` from the request's start state (with `valleys`, their exit caps
        raised)."""
        st = request.start
        cap = junction_caps(request, grid, starts, b)
        if valleys:
            valleys = raise_valley_caps(valleys, b, cap)
        # the chain's fallback feeds keep 1e-6 of each segment spare: at the exact
        # compatibility limit Ruckig's rounding refuses the zero-acceleration S-curve
        slack = 1.0 - 1e-6
        w = junction_feeds(request, grid, starts, b, slack=slack)
        if st.a == 0.0:  # and from a start at rest or cruising, reachable from there
            w[1] = min(w[1], reachable_feed(st.v, float(b.L[0]) * slack, float(b.A[0]),
                                            float(b.J[0])))
            forward_pass(w, b, slack)
        V0, A0 = first_caps(st.v, st.a, float(b.V[0]), float(b.A[0]), self.margin)
        b = replace(b, V=np.concatenate([[max(V0, b.V[0])], b.V[1:]]))
        cap[0] = st.v
        return chain(self._solver, b, cap, w, (st.v, st.a), float(cap[-1]), A0,
                     neighbour_min(b.J), neighbour_min(b.A), levels, valleys, broken)

    def _result(self, profile: FeedProfile, t_start: float, info: dict) -> PlanResult:
        return PlanResult(profile, self.name, time.perf_counter() - t_start, info)


def _first_corner(grid: PathGrid, s0: float, s1: float) -> float | None:
    """The first corner of the grid (where the machine must be at rest) in (s0, s1), or
    None."""
    ends = grid.edges[1:][grid.corner_after]
    inside = ends[(ends > s0) & (ends < s1)]
    return float(np.min(inside)) if inside.size else None


def _spans_of(fixed: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """The runs of `fixed` (valley spans) that `hit` touches (at or next to them), with
    their neighbours."""
    out = np.zeros(fixed.size, dtype=bool)
    idx = np.nonzero(hit)[0]
    n = fixed.size
    for i in idx.tolist():
        lo = hi = i
        if not fixed[i]:  # next to a span: the span on that side
            if i + 1 < n and fixed[i + 1]:
                lo = hi = i + 1
            elif i > 0 and fixed[i - 1]:
                lo = hi = i - 1
        while lo > 0 and fixed[lo - 1]:
            lo -= 1
        while hi + 1 < n and fixed[hi + 1]:
            hi += 1
        out[max(lo - 1, 0):min(hi + 2, n)] = True
    return out


def _rest_profile(s: float, dt: float) -> FeedProfile:
    """A profile that stays at s for one sample time."""
    from scipy.interpolate import PPoly

    return FeedProfile(PPoly(np.array([[0.0], [0.0], [0.0], [s]]), np.array([0.0, dt])))


def plan_rest_to_rest(path, limits, dt: float = 0.001, **kwargs) -> PlanResult:
    """Convenience: the whole path from rest to rest with the heuristic planner."""
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=dt)
    return HeuristicPlanner(**kwargs).plan(request)


__all__ = ["HeuristicPlanner", "plan_rest_to_rest"]
