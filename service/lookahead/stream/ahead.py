"""Replans computed ahead of time (real-time mode).

A replan of the plan in force does not start at the last produced sample but at a sample
`k_at` ahead of it, on the plan in force: the service computes it in a worker thread while
the plan in force keeps producing samples up to `k_at`, where the new plan takes over. What
is planned and where it takes over depend only on the engine's inputs, never on how long the
computation took: an engine that computes at once (`InlineExecutor`: fast mode, replays,
tests) produces the same batches as one with a worker thread. Only when the worker has not
finished by the time sample `k_at` is due does the engine wait for it (as every replan did
before: on the 100k-line winding program the LP's replans took up to 3.3 s on a quiet
2-core machine, and the real-time buffer held at most 1.05 s).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from concurrent.futures import Executor, Future
from dataclasses import dataclass, replace

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, Planner, PlanningError, PlanRequest
from lookahead.planning.place import describe_place, failure_s
from lookahead.stream.plans import CommittedPlan, plan_checked

log = logging.getLogger("lookahead.engine")

#: a moving replan takes over at most this far (s of motion) ahead of the last produced
#: sample while the job's geometry is still coming in ... It trades how soon new geometry
#: or a longer window is used for how long a computation may take without holding up the
#: samples: the LP's replans on the 100k-line winding program (bench/long_program.py,
#: winder3) took up to 3.3 s on a quiet 2-core machine, with 63 s of motion left in the
#: plan in force; on the fast corpus the longest replan was 1.25 s (engine-lp,
#: n-butterfly). Once the geometry is all in there is nothing to wait for and no cap: two
#: LP replans of that program took 8.6 s (cold, 2098 nodes) with 58 s of motion left, and
#: were dropped at the cap (stop 30, real time, quiet machine)
PLAN_AHEAD_MAX_S = 5.0
#: ... and at most this share of the motion the plan in force has left (a plan in force
#: looks ahead >= 2 braking distances when a replan comes, so a third of its time keeps
#: the take-over before its braking starts)
PLAN_AHEAD_SHARE = 1.0 / 3.0
#: ... or as late as this (s) before the plan in force starts its final braking, if that is
#: later: more time to compute the replan. The plan in force does not brake before, so a
#: replan taking over there loses ~nothing, and it starts from a state that is not braking
#: into the old window's end. Measured on the fast corpus's real-time engines (lp,
#: heuristic; 8 paths replan ahead): the least time a replan had beyond its computation
#: -0.061 s (c-fourier LP: late) -> +0.398 s, every path more; winding time worst +0.25 %
#: (cam-style LP), best -1.3 %; 0 fallbacks, failures, violations. 0.1 and 0.4 s moved
#: the heuristic's restarts to states it plans 1.4 and 3.0 % slower from (cam-style)
BRAKE_LEAD_S = 0.2
#: a restart from rest (new geometry after a stop at the end of what was received, a
#: resume) takes over this far ahead: the machine waits this long at rest, but its rest
#: samples keep coming while the plan is computed
RESTART_AHEAD_S = 0.5

PLANNING_ERRORS = (PlanningError, ValueError, RuntimeError, ArithmeticError)


class InlineExecutor(Executor):
    """An Executor that runs each call at once in the caller's thread (fast mode, replays,
    tests): the engine's results are the same as with a worker thread."""

    def submit(self, fn: Callable, /, *args, **kwargs) -> Future:  # type: ignore[override]
        future: Future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # handed to whoever asks for the result
            future.set_exception(exc)
        return future


@dataclass(frozen=True)
class PlanOutcome:
    """A checked plan (None if none: `error` says why); `fell_back`: it is the stop
    planner's, the configured planner failed."""

    plan: CommittedPlan | None
    error: Exception | None = None
    fell_back: bool = False

    def shifted(self, samples: int) -> PlanOutcome:
        """This outcome with its plan anchored `samples` later (`CommittedPlan.shifted`)."""
        if self.plan is None or samples == 0:
            return self
        return replace(self, plan=self.plan.shifted(samples))


def plan_with_fallback(planner: Planner, fallback: Planner, request: PlanRequest, k_plan: int,
                       tail: np.ndarray, check_limits: AxisLimits,
                       previous: CommittedPlan | None = None) -> PlanOutcome:
    """The configured planner's checked plan, else the fallback's (same request); never
    raises for a planning failure. `previous` (the plan in force) lends its verified
    samples where a plan equals it."""
    try:
        return PlanOutcome(plan_checked(planner, request, k_plan, tail, check_limits,
                                        previous))
    except PLANNING_ERRORS as exc:
        if fallback is planner:
            return PlanOutcome(None, exc)
        # a fallback is a failure of the configured planner (issue 13): counted in
        # status and job_finished, logged with the reason and the place on the path
        s_fail = failure_s(exc, request.start.s)
        log.warning("%s failed (fallback to %s) at k=%d, %s, window s=%.6g..%.6g from "
                    "v=%.6g a=%.6g: %s", planner.name, fallback.name, k_plan,
                    describe_place(request.path, s_fail), request.start.s, request.s_end,
                    request.start.v, request.start.a, exc)
    try:
        return PlanOutcome(plan_checked(fallback, request, k_plan, tail, check_limits,
                                        previous), fell_back=True)
    except PLANNING_ERRORS as exc:
        return PlanOutcome(None, exc)


def ahead_samples(k_last: int, k_end: int, batch: int, dt: float,
                  k_brake: int | None = None, cap_s: float | None = PLAN_AHEAD_MAX_S) -> int:
    """How many samples after the last produced one (`k_last`) a replan of a plan in force
    that comes to rest at `k_end` takes over: a whole number of batches (so that batches
    keep their size), 0 if less than one (then it is planned at once). k_brake: where the
    plan's final braking starts (`CommittedPlan.braking_from`): the take-over may come as
    late as BRAKE_LEAD_S before it. cap_s: at most this far ahead (None: no cap, for a
    job whose geometry is all in: PLAN_AHEAD_MAX_S)."""
    left = k_end - k_last
    if left <= 0:
        limit_s = RESTART_AHEAD_S
    else:
        limit_s = PLAN_AHEAD_SHARE * left * dt
        if k_brake is not None:
            limit_s = max(limit_s, (k_brake - k_last) * dt - BRAKE_LEAD_S)
        if cap_s is not None:
            limit_s = min(cap_s, limit_s)
    return (int(limit_s / dt + 1e-9) // batch) * batch


@dataclass(frozen=True)
class PendingPlan:
    """A replan under way: it takes over at sample `k_at` (its profile time 0), from
    `start` (the plan in force's state there) to `s_end`; `final`: the job's final length
    when it was asked for. `request` and `tail` are what `future` computes; it anchors its
    plan at `k_anchor` (the take-over it was computed for: `k_at`, or an earlier one whose
    computation this one reuses, `same_computation`)."""

    k_at: int
    start: PathState
    s_end: float
    final: float
    future: Future
    request: PlanRequest
    tail: np.ndarray
    k_anchor: int

    def outcome(self) -> PlanOutcome:
        """The finished computation's outcome, anchored at `k_at`."""
        outcome: PlanOutcome = self.future.result()
        return outcome.shifted(self.k_at - self.k_anchor)


def same_computation(pending: PendingPlan, request: PlanRequest, tail: np.ndarray,
                     final: float) -> bool:
    """Whether `pending` computes exactly what `request` from rest after `tail` asks for,
    so that its result, anchored later, is that plan: the same path object, start, end,
    limits, feed cap and sample time, a start at rest, the same published tail.

    A dropped replan whose worker goes on computing it (`Engine._take_over`) is reused
    this way by the restart from the same rest point: the restart does not queue behind
    it. Without that, a replan from rest that takes longer than RESTART_AHEAD_S was
    dropped again and again (c-fourier-xc-3000pts in real time with the LP, a 0.6 s
    window: 13 drops in a row, the machine at rest for 2 s)."""
    old = pending.request
    if pending.final != final:
        return False
    if not (request.start.v == 0.0 and request.start.a == 0.0):
        return False  # a moving start is never asked for twice (a later k_at moves it)
    if not (old.path is request.path and old.start == request.start
            and old.s_end == request.s_end and old.v_end == request.v_end
            and old.dt == request.dt and np.array_equal(pending.tail, tail)):
        return False
    lims = all(np.array_equal(getattr(old.limits, f), getattr(request.limits, f))
               for f in ("vmax", "amax", "jmax"))
    a, b = old.feed_cap, request.feed_cap
    caps = (a is None and b is None) or (
        a is not None and b is not None and np.array_equal(a.s_breaks, b.s_breaks)
        and np.array_equal(a.values, b.values))
    return lims and caps
