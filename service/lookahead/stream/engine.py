"""The deterministic core of the planner service: segments in, setpoint batches out.

No zenoh and no wall clock in here: time is the sample index k (sample k is due at k*dt
after the job's start). The service (`lookahead.service`) feeds decoded segments and
commands and asks for batches when they are due; a replay does the same from a recording.

API (stable; the replay client depends on it):

- `Engine(config, planner, realtime=False, stop_planner=None, executor=None)`; `planner`
  implements `Planner` and plans to the limits it is given (the engine applies
  `config.planner.margin` and the override); `executor` (a concurrent.futures Executor,
  default inline) computes real-time replans ahead; the batches do not depend on it.
- `submit(segment, now_s=None) -> list[Event]`: take in a decoded segment. Segments are
  recorded and listed in the next batch's `applied` field (the sample index k0 at which
  they were taken in). `now_s` (any monotonic clock, seconds) only times seq gaps.
- `expire_gaps(now_s) -> list[Event]`: fault jobs whose missing seq waited too long
  (see "Faults" below).
- `reject(reason, job=None, seq=None, **extra) -> Event`: a `rejected` event for a payload
  that did not decode (the service's decode errors) or that the service turned away.
- Delivery (PROTOCOL.md "Delivery"): `submit` ignores a resent segment with the same content
  and rejects one with different content; `announce_missing(now_s)` emits `missing` for the
  seqs that jobs wait for; `admission(segment)`, `buffered` and `full` let the service keep
  its buffer within service.max_buffered_points / max_buffered_bytes before it submits.
- `next_batch() -> SetpointBatch | None`: the next batch of the active job; None when idle,
  while a job waits for enough geometry to start (each such call counts as one batch of
  waiting, bounded by START_WAIT_S), and in fast mode (realtime=False) while starved or
  holding at rest. Real-time mode keeps emitting rest samples then.
- `command(Command) -> CommandReply` (listed in the next batch's `commands` field),
  `status() -> Status` (its `plan_complete` and `remaining_s`: "Time left" below).
- `drain_events() -> list[Event]`: every event since the last call (including those that
  `submit`/`expire_gaps`/`reject` returned): publish events from here only.

- `takeover_budget` (real time, set by the service): given the sample k at which a replan
  computed ahead takes over, how long (s, wall clock) the engine may still wait for it;
  None (the default, and fast mode): as long as it takes. A replan not done within its
  budget is dropped: the plan in force goes on (it comes to rest at its window's end if
  no later replan takes over), a new replan is computed ahead from further along (after
  LATE_MOVING_TRIES drops, from the plan's rest, reusing the dropped computation where it
  asks for the same plan), and the batch lists the dropped take-over in its `dropped`
  field (`late_replans` counts them).
- `drop_replan(job, k_at)`: replay of a recorded `dropped` take-over.

Replay: for each recorded batch, submit the segments named in its `applied` list and apply
the commands of its `commands` list, interleaved as their `after` counts say, mark its
`dropped` take-overs (`drop_replan`), then call `next_batch()` until it returns a batch;
the batches are bit-identical to the recording.

Planning (DESIGN.md "Look-ahead window"): every plan starts in the state of the last
published sample (s, ds/dt, d2s/dt2 continuous; in real-time mode a replan on time or on new
geometry starts instead on the plan in force, `stream.ahead.ahead_samples` later, and takes
over there: the `executor`, the service's worker thread, computes it meanwhile; commands
and a job's first plan are planned at once, an override in real time by a bridge from
which the configured planner's replan computed ahead takes over: the plan in force re-timed
to the new override, `_warp_bridge`, else the stop planner's plan, `_commit_command`; a
hold, abort or fault stop in real time: the plan in force re-timed to rest where that
stops within a rough braking guess, else the shortest-stop search below it) and
ends at rest inside final geometry, at min(final length, s + window): the window is
horizon_s of motion at the nominal top feed, or at the highest segment feed cap over it
where the caps hold the feed below the top feed (`_window`); every plan is
checked with the finite-difference checker against the published tail before it is
committed. If the configured planner fails, the
stop planner (heuristic) gets the same request (`fallbacks` counts these); if both fail,
the previous plan (which also ends at rest) stays in force. Cadence: a replan comes when
the plan in force looks ahead (its rest point beyond the last published sample) at most
`REPLAN_KEEP` of the window or when the window first reaches the job's end (then on new
geometry at most every REPLAN_MIN_S, else every REPLAN_EVERY_S), at once when it has come
to rest, after a resume and for an override.

Where the machine is: the last published sample. A job must start there: when a job is
about to start, its first point is compared with the machine position (per axis, within
START_TOL axis units); a job that starts elsewhere is rejected (`rejected` with seq 0 and
`job_finished` with `aborted: true`, nothing moves), since the service has no move of its
own to get there. The first job after start-up has no known position and is accepted.

Time left (status `horizon_s`, `plan_complete`, `remaining_s`): `horizon_s` is the motion
time of the committed plan from the last produced sample to where it comes to rest.
`plan_complete` is true when that rest is the end of the job: every segment is in (the
`last` one included), the plan ends at rest at the end of the path and no command waits to
change it; or the plan in force is the stop of an abort or a fault, which ends the job. Then
`remaining_s` = `horizon_s` is exact: the job's last sample comes `remaining_s` after the
last produced one (`job_finished`'s `duration_s` = k*dt + `remaining_s`, in samples). Else
`plan_complete` is false and `remaining_s` None (the plan stops short of the end, or is
about to change). Overrides: the remaining time is the plan's at the override in force; a
new override voids it (false/None) until the next batch has replanned at the new value
(through a slowdown first when the new limits cannot take over mid-motion, false/None
meanwhile). Holds: false/None from the hold command until the resume has replanned; the
remaining time counts motion only, never time spent holding.

Faults:
- A seq gap that outlasts gap_timeout_s (counted from the arrival of the first segment
  waiting behind it, while `missing` events ask for the resend) is the job's fault, not
  the machine's: `rejected` (the missing seq) and `fault` events; a job that is running
  ends at the end of the contiguous geometry it has (its window already ends at rest
  there, so this is a normal in-limit stop, not an emergency one), then `job_finished`
  with `aborted: true`; a job that has not started is dropped. The fault does not latch:
  the machine is at rest at a known position, and the next job runs only if it starts
  exactly there (the start check above), so continuing is safe. Status shows `fault`
  while the job runs out and keeps the reason in `error` until the next job starts or a
  `reset`.
- Anything else (no plan from a job's start, an internal error) latches: the active job
  stops along the path within the limits, status stays `fault` and no job starts until
  `reset`.
"""

from __future__ import annotations

import logging
import math
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Executor, Future, wait
from dataclasses import dataclass, field, replace

import numpy as np

from lookahead.checker import check_positions
from lookahead.config import Config
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, Planner, PlanRequest, PlanResult
from lookahead.planning.heuristic import HeuristicPlanner  # at start-up, not per job
from lookahead.planning.lp.envelope import braking_distance as s_curve_braking_distance
from lookahead.protocol import Command, CommandReply, Event, Segment, SetpointBatch, Status
from lookahead.sampling import sample_profile
from lookahead.stream.ahead import (
    PLAN_AHEAD_MAX_S,
    InlineExecutor,
    PendingPlan,
    PlanOutcome,
    ahead_samples,
    plan_with_fallback,
    same_computation,
)
from lookahead.stream.assembler import (
    JobGeometry,
    SegmentOrder,
    SegmentRejectedError,
    segment_size,
)
from lookahead.stream.plans import (
    S_TOL,
    CommittedPlan,
    braking_guess,
    rest_plan,
    shortest_stop,
    verify,
    warped_profile,
)

log = logging.getLogger("lookahead.engine")

#: replan at least this often while the window end can move (s of motion)
REPLAN_EVERY_S = 0.1
#: ... but only once the plan in force looks ahead (its rest point beyond the last
#: published sample) at most this fraction of the window, or at most REPLAN_KEEP_BRAKING
#: braking distances (`braking_distance`), whichever is longer. It trades compute for
#: (nearly) nothing: a plan hardly depends on its window end more than a braking distance
#: ahead (the window is >= 3 of them), and a replan every 0.1 s re-planned, re-sampled and
#: re-checked each stretch of path 20-40 times (the window is 2 s at the top feed, often
#: 4 s of motion). Measured on the fast corpus (14 paths, heuristic and LP engines, the
#: planners of 2026-12-02, same code either way): replans 3-9 per path instead of 28-93;
#: winding time / a replan every 0.1 s worst 1.0028 (LP c-rand2), 1.0023 (heuristic
#: cam-style), best 0.960 (LP cam-fp-hoop: fewer restarts from a moving state); 0
#: fallbacks, failed replans, violations either way; 0.75 and 0.9 were no better on the
#: worst paths (c-rand2, c-rand6). Paths within one window are unchanged (one plan).
REPLAN_KEEP = 0.5
REPLAN_KEEP_BRAKING = 2.0
#: and no more often than this on new geometry alone
REPLAN_MIN_S = 0.02
#: real time: replans computed ahead for a moving take-over dropped in a row (as late)
#: after which the next one takes over once the plan in force is at rest. Each new try,
#: a third of the remaining motion ahead, has less time than the last and waits for the
#: dropped computation: with replans 3x slower than their budget, 12 tries were dropped
#: on the way to rest (tests/test_late_replan.py)
LATE_MOVING_TRIES = 2
#: a replan computed ahead (real time) does not take over where the plan in force
#: decelerates harder than this share of its strongest deceleration, where it can: it
#: takes over at the latest whole batch before `ahead_samples`' take-over that does not
#: (no earlier than half of it). Why: replans from a braking into a turnaround lock were
#: the LP's slowest (the 20k-line program: 19 of 820, median 68 ms against 7 ms, all of
#: its p99) and the ones that failed (tests/test_lp_feasibility.py). At 0.25 the
#: take-overs moved to the braking's first ms, as slow (up to 1.3 s); at 0.02: none from
#: a braking, replan p99 108 -> 86 ms, motion 1296.2 -> 1295.3 s; fast corpus within
#: 0.07 %. (Fast mode postponing a due replan out of a braking, as well, cost cam-style
#: 0.9 % with the heuristic: not done.)
TAKE_OVER_BRAKING_SHARE = 0.02
#: a job starts when `last` is in, its final geometry covers the horizon, or after this
START_WAIT_S = 0.5
#: during an override change that needs a slowdown first, retry the new limits this often
TRANSITION_RETRY_S = 0.03
#: real time: an override's bridge is first the plan in force re-timed to the new override
#: (`Engine._warp_bridge`), its rate ramped over the first of these durations (s) whose
#: ramp passes the checker
WARP_RAMPS_S = (0.05, 0.1, 0.2, 0.4, 0.8, 1.6)
#: real time: a hold, abort or fault stop is first the plan in force re-timed to rest
#: (`stop_ramps`): its rate r ramps from 1 to 0 as an S-curve whose |r'| and |r''| are the
#: path acceleration and jerk the axes allow along the tangent where the stop starts, over
#: the path speed, stretched by the first of these factors whose samples pass the checker
#: (curvature, a turning tangent and the plan's own acceleration take part of the limits).
#: Steps of <= 1.33x: a stop at most a third longer than the ramp's shortest passing one
STOP_STRETCH = (1.0, 1.15, 1.33, 1.6, 2.0, 2.5, 3.2, 4.0, 5.3, 7.0, 9.3, 12.0, 16.0)
#: the shortest stop ramp (s): from a crawl the S-curve would be shorter than a few samples
STOP_RAMP_MIN_S = 0.01
#: job ids remembered as finished (later segments of them are rejected)
MAX_DONE = 4096
#: a job's first point may differ from the machine position by this much per axis (axis
#: units; the end of a path is sampled to ~1e-12, so this only absorbs rounding)
START_TOL = 1e-6


@dataclass
class _Job:
    """One job: its assembly and, once started, its run state (k = next sample)."""

    id: str
    order: SegmentOrder
    geo: JobGeometry
    wait: int = 0
    started: bool = False
    k: int = 0
    batch_seq: int = 0
    plan: CommittedPlan | None = None
    tail: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    planned_final: float = 0.0
    stop: str | None = None  # why the current plan is a stop: hold, abort, fault, override
    stop_request: str | None = None
    hold: bool = False
    fault: str | None = None
    starved: bool = False
    force_replan: bool = False
    override_pending: bool = False
    #: the override the plan in force was planned at, while an override waits for its replan
    override_from: float = 1.0
    #: the plan in force is a stop (`_begin_stop`: planned at the full limits, not at the
    #: override): an override does not re-time it (`_warp_bridge`)
    stop_in_force: bool = False
    last_try: int = 0
    last_fail: int = -(10**9)  # sample index of the last failed replan (retry backoff)
    fallbacks_at_start: int = 0  # engine.fallbacks when the job started (job_finished)
    handovers_at_start: int = 0  # engine.handovers then
    late_at_start: int = 0  # engine.late_replans then
    #: take-overs dropped as late since a replan was last adopted (`_take_over`)
    late: int = 0
    #: the plan in force once it ends at the end of the finished geometry: no replan
    #: extends it (`Engine._maybe_replan`), only a command or a stop replaces it
    settled: CommittedPlan | None = None
    #: (plan, whether it ends at the end of the finished geometry) for `Engine._ending`
    ends_job: tuple[CommittedPlan, bool] | None = None
    #: (final_length, tolerance) once the geometry is finished (`Engine._finished_end`)
    end_memo: tuple[float, float] | None = None
    #: real-time mode: the replan under way, which takes over at its `k_at` (stream/ahead.py)
    pending: PendingPlan | None = None
    #: (plan, how far it may look ahead before a replan is due) (`Engine._plan_keep`)
    keep_memo: tuple[CommittedPlan, float] | None = None
    #: the last replan dropped as late, whose computation goes on: the next replan reuses
    #: it if it asks for the same (`ahead.same_computation`), else it is cancelled
    abandoned: PendingPlan | None = None


class Engine:
    """Segments -> look-ahead plans -> setpoint batches; see the module docstring."""

    def __init__(self, config: Config, planner: Planner, realtime: bool = False,
                 stop_planner: Planner | None = None, executor: Executor | None = None
                 ) -> None:
        m = config.machine
        self.config = config
        self.planner = planner
        search_planner = stop_planner
        #: the fallback of replans computed ahead: planners are not thread-safe, so a
        #: worker never shares one with the stops that the engine plans meanwhile
        self._ahead_fallback = stop_planner
        if stop_planner is None:
            stop_planner = HeuristicPlanner(margin=1.0, continue_last=False)
            search_planner = HeuristicPlanner(margin=1.0, brake_within_limits=False,
                                              continue_last=False)
            self._ahead_fallback = (HeuristicPlanner(margin=1.0, continue_last=False)
                                    if realtime else stop_planner)
        assert self._ahead_fallback is not None
        #: runs the replans computed ahead (real-time mode); the service passes a worker
        #: thread, anything else computes them at once, with the same results
        self.executor = executor or InlineExecutor()
        self._inflight: Future | None = None  # the last replan handed to the executor
        #: replans computed ahead that were not done at their take-over (the engine waited)
        self.takeover_waits = 0
        #: real time (the service's pacer): seconds the engine may still wait for a replan
        #: computed ahead whose take-over sample is k; None: no limit (module docstring)
        self.takeover_budget: Callable[[int], float | None] | None = None
        #: replans computed ahead dropped because they were not done within their budget
        #: (the plan in force went on): in status, job_finished and the batches' `dropped`
        self.late_replans = 0
        self._dropped: list[int] = []  # take-overs dropped since the last batch
        self._drop_marks: set[tuple[str, int]] = set()  # replay: take-overs to drop
        self.stop_planner = stop_planner
        #: the shortest-stop search's first try (fast-failing trials, `_begin_stop`)
        self.stop_search_planner = search_planner
        self.realtime = realtime
        self.dt = m.dt
        self.axes = tuple(m.axes)
        self.limits = m.limits
        self.path_scale = np.asarray(m.path_scale, dtype=float)
        self.batch = config.service.batch
        self.margin = config.planner.margin
        self.horizon_len = horizon_length(self.limits, self.path_scale, config.planner.horizon_s)
        self.horizon_s = config.planner.horizon_s
        self._top_feed = float(np.linalg.norm(self.limits.vmax * self.path_scale))
        #: replan (on time or new geometry) only when the plan looks ahead less than this
        self._keep = max(REPLAN_KEEP * self.horizon_len,
                         REPLAN_KEEP_BRAKING * braking_distance(self.limits, self.path_scale))
        self._every = max(1, round(REPLAN_EVERY_S / self.dt))
        self._min_gap = max(1, round(REPLAN_MIN_S / self.dt))
        self._start_wait = max(1, round(START_WAIT_S / self.dt))
        self._retry = max(1, round(TRANSITION_RETRY_S / self.dt))
        self._jobs: OrderedDict[str, _Job] = OrderedDict()
        self._done: OrderedDict[str, str] = OrderedDict()  # job id -> "finished" / ...
        self._active: _Job | None = None
        self._events: list[Event] = []
        self._applied: list[tuple[str, int]] = []
        self._commands: list[tuple[str, float | None, int]] = []
        self.override = 1.0
        self.fault: str | None = None
        self.plan_ms = 0.0
        self.replans = 0
        self.replan_failures = 0
        self.fallbacks = 0
        #: LP plans whose start the heuristic's transient took (`lp.handover`): not a
        #: failure, logged at INFO and counted in job_finished
        self.handovers = 0
        #: commands planned at once by the stop planner in real time while the configured
        #: planner's replan is computed ahead (`_commit_command`)
        self.bridges = 0
        #: bridge overrides in real time (`_commit_command`); off: the configured planner
        #: plans them at once, as before (bench/override_latency.py's A/B partner)
        self.bridge_overrides = True
        #: real time: holds, aborts and fault stops re-time the plan in force to rest
        #: (`_retimed`) before they search the shortest stop; off: the search at once, as
        #: before (bench/stop_latency.py's A/B partner)
        self.warp_stops = True
        self._last_k = 0
        self._last_job: str | None = None
        self._position: np.ndarray | None = None  # last published sample, None at start-up
        self._job_error: str | None = None  # a job-scoped fault, shown until the next job
        self._receiving: str | None = None  # the job of the last segment taken in
        self._buffered = (0, 0)  # see `buffered`

    # --- input ------------------------------------------------------------------------
    def submit(self, seg: Segment, now_s: float | None = None) -> list[Event]:
        """Take in one decoded segment; returns the events it caused (also queued)."""
        mark = len(self._events)
        self._applied.append((seg.job, seg.seq))
        if tuple(seg.axes) != self.axes:
            self._reject(seg.job, seg.seq, f"axes: must equal the machine's axes "
                         f"{list(self.axes)}, got {list(seg.axes)}")
            return self._events[mark:]
        if seg.job in self._done:
            self._reject(seg.job, seg.seq, f"job: {seg.job!r} {self._done[seg.job]}")
            return self._events[mark:]
        job = self._jobs.get(seg.job)
        if job is None:
            order = SegmentOrder(seg.job, self.config.service.gap_timeout_s)
            geo = JobGeometry(seg.job, self.axes, self.path_scale, self.config.planner.fit,
                              self.config.planner.tolerance)
            job = _Job(seg.job, order, geo, tail=np.empty((0, len(self.axes))))
        fresh = job.order.admission(seg) != "duplicate"
        try:
            ready = job.order.offer(seg, now_s)
        except SegmentRejectedError as exc:
            self._reject(seg.job, exc.seq, exc.reason)
            ready, fresh = [], False
        if fresh:
            size = segment_size(seg)
            self._buffered = (self._buffered[0] + size[0], self._buffered[1] + size[1])
        while ready:
            nxt = ready.pop()
            try:
                job.geo.add(nxt)
            except SegmentRejectedError as exc:
                job.order.refused(nxt)
                self._reject(job.id, nxt.seq, exc.reason)
                continue
            for warning in job.geo.drain_warnings():  # fit excursions (cubic, pchip)
                self._emit("warning", job.id, self._last_k, **warning)
            ready = job.order.accepted(nxt)
        if job.geo.nsegments or job.order.waiting:
            self._jobs.setdefault(job.id, job)
            self._receiving = job.id
        return self._events[mark:]

    def admission(self, seg: Segment) -> str:
        """How `submit` would treat `seg` by its job and seq: `duplicate` (a seq the job
        already has), `gap` (it fills a gap that waiting segments sit behind) or `new`
        (the service takes `new` ones only while its buffer is not full)."""
        job = self._jobs.get(seg.job)
        return "new" if job is None else job.order.admission(seg)

    def announce_missing(self, now_s: float) -> list[Event]:
        """`missing` events for the seqs that jobs wait for (PROTOCOL.md "Delivery"): new
        gaps at once, open ones again every MISSING_REPEAT_S."""
        mark = len(self._events)
        for job in self._jobs.values():
            if job.fault is None and job.order.waiting:
                k = max(job.k - 1, 0) if job is self._active else 0
                for seq in job.order.announce(now_s):
                    self._emit("missing", job.id, k, seq=seq)
        return self._events[mark:]

    @property
    def buffered(self) -> tuple[int, int]:
        """(points, bytes) received but not executed, as of the last `status()` plus what
        came in since (an upper bound between two `status()` calls)."""
        return self._buffered

    def _count_buffered(self, job: _Job | None, s_now: float) -> tuple[int, int]:
        points, nbytes = 0, 0
        for j in self._jobs.values():
            p, b = (j.geo.unexecuted_size(s_now, self._tol(j)) if j is job
                    else j.geo.unexecuted_size(None))
            points += p + j.order.pending_points
            nbytes += b + j.order.pending_bytes
        return points, nbytes

    def expire_gaps(self, now_s: float) -> list[Event]:
        """Fault every job whose missing seq has waited longer than gap_timeout_s."""
        mark = len(self._events)
        for job in list(self._jobs.values()):
            if job.fault is None and job.order.overdue(now_s):
                self._seq_fault(job, f"seq: segment {job.order.expected} of job {job.id!r} "
                                f"did not arrive within {job.order.gap_timeout_s} s")
        return self._events[mark:]

    def reject(self, reason: str, job: str | None = None, seq: int | None = None,
               **extra) -> Event:
        """A `rejected` event for a message that could not be decoded or was turned away."""
        return self._reject(job, seq, reason, **extra)

    def drain_events(self) -> list[Event]:
        out, self._events = self._events, []
        return out

    # --- output -----------------------------------------------------------------------
    def next_batch(self) -> SetpointBatch | None:
        """The next batch (see the module docstring for when it is None)."""
        if self._active is None:
            if self.fault is not None or not self._jobs:
                return None
            job = next(iter(self._jobs.values()))
            if job.geo.first_point is not None and self._reject_elsewhere(job):
                return None
            if not self._ready_to_start(job):
                return None
            if job.geo.empty:
                return self._empty_job(job)
            self._active = job
            job.started = True
            job.fallbacks_at_start = self.fallbacks
            job.handovers_at_start = self.handovers
            job.late_at_start = self.late_replans
            self._job_error = None
            self._emit("job_started", job.id, 0)
        return self._produce(self._active)

    def _reject_elsewhere(self, job: _Job) -> bool:
        """Reject (and drop) a job about to start whose first point is not where the
        machine is; True if it was rejected."""
        first, here = job.geo.first_point, self._position
        if here is None or np.all(np.abs(first - here) <= START_TOL):
            return False
        field_name = "points[0]" if job.geo.kind == "points" else "ctrl[0]"
        self._reject(job.id, 0, f"{field_name}: job {job.id!r} starts at "
                     f"{_fmt(first)} {list(self.axes)} but the machine is at {_fmt(here)} "
                     f"(where the last job left it); a job must start where the machine is")
        self._emit("job_finished", job.id, 0, duration_s=0.0, aborted=True)
        self._drop(job, "was rejected (it does not start where the machine is)")
        return True

    def _ready_to_start(self, job: _Job) -> bool:
        geo = job.geo
        if geo.finished:
            return True
        if geo.path() is None:
            return False
        if geo.final_length >= self.horizon_len or job.wait >= self._start_wait:
            return True
        job.wait += self.batch
        return False

    def _empty_job(self, job: _Job) -> SetpointBatch:
        """A job without motion: one sample at rest on its point."""
        point = job.geo.first_point if job.geo.first_point is not None else np.zeros(
            len(self.axes))
        zeros = np.zeros((1, len(self.axes)))
        batch = SetpointBatch(job.id, 0, 0, self.dt, self.axes, point.reshape(1, -1), zeros,
                              zeros.copy(), True, *self._take_inputs())
        self._position = point.copy()
        self._last_k, self._last_job, self._job_error = 0, job.id, None
        self._emit("job_started", job.id, 0)
        self._finish(job, aborted=False)
        return batch

    def _produce(self, job: _Job) -> SetpointBatch | None:
        self._take_over(job)
        self._maybe_replan(job)
        plan = job.plan
        assert plan is not None
        k0, n = job.k, self.batch
        if job.pending is not None:  # the plan in force produces up to k_at
            n = min(n, job.pending.k_at + 1 - k0)
        final = False
        if self._ending(job):
            n = max(1, min(n, plan.k_end - k0 + 1))
            final = k0 + n - 1 >= plan.k_end
        elif not self.realtime and (job.hold or job.starved or self._at_sent_end(job)):
            n = min(n, plan.k_end - k0 + 1)
            if n <= 0:
                return None
        smp = plan.samples(k0, n, self.dt)
        batch = SetpointBatch(job.id, job.batch_seq, k0, self.dt, self.axes, smp.pos, smp.vel,
                              smp.acc, final, *self._take_inputs(), dropped=tuple(self._dropped))
        self._dropped.clear()
        job.k += n
        job.batch_seq += 1
        job.tail = (smp.pos[-3:].copy() if n >= 3 else np.vstack([job.tail, smp.pos])[-3:])
        self._position = smp.pos[-1].copy()
        self._last_k, self._last_job = job.k - 1, job.id
        if final:
            self._finish(job, aborted=job.stop in ("abort", "fault") or job.fault is not None)
        elif (job.k - 1 >= plan.k_end and not job.hold and not job.starved
              and self._at_sent_end(job)):
            job.starved = True
            self._emit("starved", job.id, job.k - 1)
        return batch

    def _ending(self, job: _Job) -> bool:
        """True when the committed plan ends the job (path end reached or a stop)."""
        if job.stop in ("abort", "fault"):
            return True
        if job.hold or job.stop is not None or not job.geo.finished:
            return False
        memo = job.ends_job  # finished geometry does not change: once per plan
        if memo is None or memo[0] is not job.plan:
            path = job.geo.path()
            memo = (job.plan, path is not None
                    and job.plan.s_end >= path.length - self._tol(job))
            job.ends_job = memo
        return memo[1]

    def _at_sent_end(self, job: _Job) -> bool:
        """The plan stops at the end of everything received, and the job is not complete."""
        geo = job.geo
        if geo.finished:
            return False
        # everything received extends the final geometry (sent_length >= final_length),
        # and x - S_TOL max(x, 1) grows with x: a plan that stops this far short of the
        # final length stops short of the sent one too, without building the live path
        final = geo.final_length
        if job.plan.s_end < final - 2.0 * S_TOL * max(final, 1.0):
            return False
        return job.plan.s_end >= geo.sent_length - self._tol(job)

    def _finished_end(self, job: _Job) -> tuple[float, float]:
        """(final_length, `_tol`) of a job whose geometry is finished (constants then)."""
        if job.end_memo is None:
            assert job.geo.finished
            job.end_memo = (job.geo.final_length, self._tol(job))
        return job.end_memo

    def _tol(self, job: _Job) -> float:
        return S_TOL * max(job.geo.sent_length, 1.0)

    def _take_inputs(self) -> tuple[tuple[tuple[str, int], ...],
                                    tuple[tuple[str, float | None, int], ...]]:
        """The segments and commands taken in since the last batch (its `applied` and
        `commands` fields)."""
        out = tuple(self._applied), tuple(self._commands)
        self._applied.clear()
        self._commands.clear()
        return out

    # --- planning ---------------------------------------------------------------------
    def _plan_limits(self) -> AxisLimits:
        """Limits the planner plans to: margin, and the override as a time scaling
        (v f, a f^2, j f^3) for f < 1."""
        lim = self.limits.scaled(self.margin)
        f = min(self.override, 1.0)
        return AxisLimits(lim.vmax * f, lim.amax * f * f, lim.jmax * f**3)

    def _request(self, job: _Job, start: PathState, s_end: float) -> PlanRequest:
        path = job.geo.path()
        return PlanRequest(path, self._plan_limits(), start, s_end, 0.0,
                           job.geo.feed_cap(self.override), self.dt)

    def _commit(self, job: _Job, start: PathState, s_end: float, k_plan: int) -> bool:
        """Plan [start.s, s_end] anchored at k_plan now; keep the old plan if it fails."""
        self._planner_free()
        request = self._request(job, start, s_end)
        outcome = plan_with_fallback(self.planner, self.stop_planner, request, k_plan,
                                     job.tail, self.limits, job.plan)
        return self._adopt(job, outcome, start, s_end, k_plan, job.geo.final_length)

    def _commit_command(self, job: _Job, start: PathState, s_end: float, k_plan: int
                        ) -> bool:
        """`_commit` for a command's replan of a moving machine (an override). In real-time
        mode with a configured planner other than the stop planner (the LP), the stop
        planner plans it at once (a bridge: the heuristic, tens of ms, where an LP solve can
        take seconds, longer than the buffer) and the configured planner's replan computed
        ahead takes over from the bridge (`_replan`; its start is a state of the
        heuristic's plan, which the LP hands over where it cannot follow it, `lp.handover`).
        The bridge is not a fallback: the configured planner was not asked."""
        if not (self.realtime and self.bridge_overrides) or self.planner is self.stop_planner:
            return self._commit(job, start, s_end, k_plan)
        if self._ahead_fallback is self.stop_planner:
            self._planner_free()  # (a worker without its own fallback planner)
        request = self._request(job, start, s_end)
        outcome = plan_with_fallback(self.stop_planner, self.stop_planner, request, k_plan,
                                     job.tail, self.limits, job.plan)
        if not self._adopt(job, outcome, start, s_end, k_plan, job.geo.final_length):
            return False
        self.bridges += 1
        plan = job.plan
        assert plan is not None
        if k_plan < plan.k_end:
            self._replan(job, plan, k_plan, plan.state(k_plan, self.dt), s_end)
        return True

    def _warp_bridge(self, job: _Job, k_last: int, state: PathState, target: float
                     ) -> bool:
        """Real time, an override of a moving plan (not a stop): bridge it by the plan in
        force re-timed (`plans.warped_profile`): its rate ramps from 1 to the ratio of the
        new override's limits to the old one's, then it runs time-scaled by that ratio, so
        it keeps the new limits (as its planner kept the old ones) to its rest. No planner
        call: a heuristic bridge from such a state took seconds on hard paths (B-spline
        corners: up to 8 s per attempt, failing), longer than the buffer. The ramp is the
        shortest of WARP_RAMPS_S whose samples pass the checker (at the limits, as every
        transition of an override); then the whole plan is checked. The configured
        planner's replan computed ahead takes over from it after the ramp. False (nothing
        changed) where it does not apply or no ramp passes."""
        plan = job.plan
        if (not (self.realtime and self.bridge_overrides) or self.planner is self.stop_planner
                or plan is None or job.stop is not None or job.stop_in_force
                or k_last >= plan.k_end):
            return False
        t_start = time.perf_counter()
        f_old, f_new = job.override_from, self.override
        if not (f_old > 0 and f_new > 0):
            return False
        ratio = min(f_new, 1.0) / min(f_old, 1.0)  # the limits' time scaling
        if job.geo.feed_cap() is not None:  # segment feeds scale with the override itself
            ratio = min(ratio, f_new / f_old)
        found = self._retimed(plan, k_last, job.tail, ratio,
                              [(ramp, 0.0) for ramp in WARP_RAMPS_S], "override")
        if found is None:
            return False
        bridge, ramp, t_ramp = found
        self._adopt(job, PlanOutcome(bridge), state, bridge.s_end, k_last, job.planned_final)
        self.bridges += 1
        log.info("override %.3g -> %.3g job=%s k=%d: the plan in force re-timed by %.4g "
                 "(ramp %.3g s, %.1f ms)", f_old, f_new, job.id, k_last, ratio, ramp,
                 1e3 * (time.perf_counter() - t_start))
        if k_last < bridge.k_end:
            self._replan(job, bridge, k_last, state, target,
                         not_before=k_last + math.ceil(t_ramp / self.dt))
        return True

    def _retimed(self, plan: CommittedPlan, k_last: int, tail: np.ndarray, ratio: float,
                 ramps: list[tuple[float, float]], label: str
                 ) -> tuple[CommittedPlan, float, float] | None:
        """The plan in force from sample k_last on, its rate ramped from 1 to `ratio` (0: a
        stop) by the first of `ramps` ((duration, of which at constant r') s) whose samples
        pass the checker after `tail` (`plans.warped_profile`), verified whole: (plan, ramp,
        the ramp's end in its time), or None if no ramp passes or the plan has ended."""
        t_start = time.perf_counter()
        t0 = (k_last - plan.k_plan) * self.dt
        if not t0 < plan.profile.duration:
            return None
        for ramp, flat in ramps:
            profile, t_ramp = warped_profile(plan.profile, t0, ratio, ramp, self.dt, flat)
            n_ramp = math.ceil(t_ramp / self.dt) + 3
            pos = sample_profile(plan.path, profile, np.arange(1, n_ramp + 1) * self.dt).pos
            if not check_positions(np.vstack([tail, pos]) if tail.size else pos,
                                   self.limits, self.dt).ok:
                continue
            result = PlanResult(profile, label, time.perf_counter() - t_start,
                                {"ratio": ratio, "ramp_s": ramp})
            retimed, k_new = CommittedPlan.anchor(plan.path, result, k_last,
                                                  self.dt).with_samples(self.dt, plan)
            if verify(retimed, tail, self.limits, self.dt, k_new):
                continue
            return retimed, ramp, t_ramp
        return None

    def _adopt(self, job: _Job, outcome: PlanOutcome, start: PathState, s_end: float,
               k_plan: int, final: float) -> bool:
        """Put a replan's outcome in force (or count its failure: the old plan stays);
        `final`: the job's final length the replan saw."""
        if outcome.fell_back:
            self.fallbacks += 1
        if outcome.plan is None:
            self.replan_failures += 1
            job.last_fail = k_plan
            log.log(logging.DEBUG if job.stop == "override" else logging.WARNING,
                    "replan failed job=%s k=%d s=%.6g..%.6g: %s", job.id, k_plan,
                    start.s, s_end, outcome.error)
            return False
        if outcome.plan.handover is not None and not outcome.fell_back:
            self.handovers += 1
            h = outcome.plan.handover
            log.info("%s start handed over job=%s k=%d s=%.6g v=%.6g a=%.6g: the heuristic's "
                     "transient to s=%.6g (%.1f %% of the plan's time%s); the LP had failed: %s",
                     self.planner.name, job.id, k_plan, start.s, start.v, start.a, h["s"],
                     100.0 * h["share"], ", a committed stop" if h["whole"] else "",
                     h["reason"])
        if job.late:
            log.warning("real time: a replan took over again at k=%d (job %s) after %d "
                        "dropped as late", k_plan, job.id, job.late)
        job.plan = outcome.plan
        job.stop_in_force = False
        job.late = 0
        job.planned_final = final
        job.force_replan = False
        self.replans += 1
        self.plan_ms = outcome.plan.compute_s * 1e3
        return True

    def _replan(self, job: _Job, plan: CommittedPlan, k_last: int, state: PathState,
                target: float, not_before: int | None = None) -> None:
        """A replan on time or on new geometry: in real-time mode computed ahead (it takes
        over `ahead_samples` later, from the plan in force's state there), else now.
        not_before: take over no earlier than this sample where the plan in force still
        moves there (in whole batches; the end of an override's ramp, `_warp_bridge`)."""
        # after an override's ramp (`not_before`) the configured planner takes over as
        # soon as the ramp ends, not as late as the re-timed plan's braking allows: the
        # re-timing keeps the new limits only to the checker's rounding where the ramp
        # joins the time-scaled plan (0.25 % over the jerk limit, heuristic)
        ahead = ahead_samples(
            k_last, plan.k_end, self.batch, self.dt,
            plan.braking_from(self.dt) if not_before is None else None,
            None if job.geo.finished else PLAN_AHEAD_MAX_S) if self.realtime else 0
        if ahead > 0 and not_before is not None and k_last + ahead < not_before:
            later = -(-(not_before - k_last) // self.batch) * self.batch
            if k_last + later < plan.k_end:
                ahead = later
        if k_last < plan.k_end and job.late and (ahead <= 0 or job.late >= LATE_MOVING_TRIES):
            # after a dropped take-over the worker may still be running it: planning at
            # once would wait for it. Take over once the plan in force is at rest instead
            # (also after LATE_MOVING_TRIES drops: each try nearer the rest point has less
            # time, and queues behind the dropped computation)
            ahead = (-(-(plan.k_end - k_last) // self.batch) * self.batch
                     + ahead_samples(plan.k_end, plan.k_end, self.batch, self.dt))
        if ahead <= 0:
            if self._commit(job, state, target, k_last):
                job.starved = False
            return
        if not_before is None and not job.late:
            ahead = self._calm_ahead(plan, k_last, ahead)
        k_at = k_last + ahead
        start = plan.state(k_at, self.dt)
        final = job.geo.final_length
        s_end = self._window_end(job, start.s, final)
        request = self._request(job, start, s_end)
        tail = plan.samples(k_at - 2, 3, self.dt).pos
        old, job.abandoned = job.abandoned, None
        if old is not None and same_computation(old, request, tail, final):
            # the dropped computation goes on and takes over here once done (a replay,
            # which computed it at once, reuses it the same way)
            job.pending = replace(old, k_at=k_at)
            return
        if old is not None:
            # not started: never runs (its planners' forget() is queued after it, so a
            # replay, which computed it, starts the next replan alike)
            old.future.cancel()
        future = self.executor.submit(plan_with_fallback, self.planner, self._ahead_fallback,
                                      request, k_at, tail, self.limits, plan)
        self._inflight = future
        job.pending = PendingPlan(k_at, start, s_end, final, future, request, tail, k_at)

    def _calm_ahead(self, plan: CommittedPlan, k_last: int, ahead: int) -> int:
        """`ahead` (samples, whole batches) moved back to the latest whole batch at least
        half as far ahead whose state is not in the plan's hard braking
        (TAKE_OVER_BRAKING_SHARE); `ahead` itself if none is."""
        steps = np.arange(ahead, max(ahead // 2, self.batch) - 1, -self.batch)
        steps = steps[(steps > 0) & (k_last + steps < plan.k_end)]
        if steps.size == 0:
            return ahead
        calm = ~plan.braking_hard(k_last + steps, self.dt, TAKE_OVER_BRAKING_SHARE)
        return int(steps[np.argmax(calm)]) if calm.any() else ahead

    def _take_over(self, job: _Job) -> None:
        """The replan under way takes over once its sample k_at is produced: waiting for
        it if it is not done, for at most `takeover_budget(k_at + 1)`; past that (or where
        a replay marks it, `drop_replan`) it is dropped and the plan in force goes on."""
        pending = job.pending
        if pending is None or job.k <= pending.k_at:
            return
        job.pending = None
        marked = (job.id, pending.k_at) in self._drop_marks
        self._drop_marks.discard((job.id, pending.k_at))
        if not marked and not pending.future.done():
            self.takeover_waits += 1
            budget = self.takeover_budget(pending.k_at + 1) if self.takeover_budget else None
            wait([pending.future], timeout=None if budget is None else max(budget, 0.0))
            marked = not pending.future.done()
        if marked:
            # the plan in force is checked and ends at rest: going on with it slows the
            # machine where the replan would not have, but never starves it. The planners
            # saw the dropped request (a replay computes it too), so their state (the
            # LP's seams) is the same in a replay; the next replan starts on the plan in
            # force, which the LP's seam check tells from the dropped plan.
            self.late_replans += 1
            self._dropped.append(pending.k_at)
            job.late += 1
            # its computation goes on: the restart from the same rest point reuses it
            # (`_replan`), any other replan cancels it if it has not started. The planners
            # forget their last plan, computed (a replay) or not (cancelled), so that the
            # next replan starts alike in both
            job.abandoned = pending
            self._forget_plans()
            plan = job.plan
            assert plan is not None
            log.log(logging.WARNING if job.late == 1 else logging.DEBUG,
                    "real time: the replan computed ahead to take over at k=%d (job %s, "
                    "s=%.6g) was not done in time: dropped, the plan in force goes on (at "
                    "rest at k=%d unless a later replan takes over)", pending.k_at, job.id,
                    pending.start.s, plan.k_end)
            return
        if self._adopt(job, pending.outcome(), pending.start, pending.s_end,
                       pending.k_at, pending.final):
            job.starved = False

    def drop_replan(self, job: str, k_at: int) -> None:
        """Replay: drop the replan computed ahead that takes over at `k_at` in `job` (a
        recorded batch's `dropped` field), as the recorded service did when it was late."""
        self._drop_marks.add((job, k_at))

    def _planner_free(self) -> None:
        """Wait until no replan under way uses the planners (they are not thread-safe)."""
        if self._inflight is not None:
            wait([self._inflight])
            self._inflight = None

    def _maybe_replan(self, job: _Job) -> None:
        geo = job.geo
        if job.plan is None:
            self._first_plan(job)
            return
        k_last = job.k - 1
        plan = job.plan
        at_rest = k_last >= plan.k_end
        if job.stop_request is not None:
            self._begin_stop(job, job.stop_request)
            job.stop_request = None
            return
        if job.stop in ("abort", "fault") or job.hold:
            return
        if job.override_pending or job.stop == "override":
            job.pending = None  # planned at the old override
        if job.stop == "override":
            if at_rest:
                job.stop = None
            else:
                if k_last - job.last_try >= self._retry:
                    job.last_try = k_last
                    state = plan.state(k_last, self.dt)
                    target = self._window_end(job, state.s, geo.final_length)
                    if target > state.s and self._commit_command(job, state, target, k_last):
                        job.stop = None
                return
        if job.override_pending:
            job.override_pending = False
            state = plan.state(k_last, self.dt)
            target = self._window_end(job, state.s, geo.final_length)
            if target > state.s + self._tol(job) and not self._warp_bridge(
                    job, k_last, state, target) and not self._commit_command(
                    job, state, target, k_last):
                self._begin_stop(job, "override")
                job.last_try = k_last
            return
        if job.pending is not None:
            return  # a replan is under way: it takes over at its k_at
        # the two common cases of every batch, decided without building the geometry
        # (which new segments make stale) and without the path state: they return where
        # the checks below would return too
        if job.settled is plan:
            return  # the plan reaches the end of the finished path (see below)
        if not (at_rest or job.force_replan):
            s = plan.s_at(k_last, self.dt)
            if plan.s_end - s > self._plan_keep(job, plan):
                if not geo.finished:
                    return  # it looks ahead more than `_keep`, no window reaches the end
                final, tol = self._finished_end(job)
                if s + self.horizon_len < final - tol:
                    return  # ... and the next window would not reach the end either
        state = plan.state(k_last, self.dt)
        final = geo.final_length
        if at_rest and plan.s_end >= final - self._tol(job) and geo.freeze():
            final = geo.final_length
        target = self._window_end(job, state.s, final)
        if target <= plan.s_end + self._tol(job):
            if geo.finished and final <= plan.s_end + self._tol(job):
                # finished geometry does not change: every later target (<= final) is
                # within this plan too, until a command or a new plan
                job.settled = plan
            return
        since = k_last - plan.k_plan
        # the window reaches the job's end: plan it now (its exact time left, status
        # `plan_complete`), else only once the plan in force looks ahead <= REPLAN_KEEP
        to_end = geo.finished and target >= final - self._tol(job)
        if not (at_rest or job.force_replan or to_end) and (
                plan.s_end - state.s > self._plan_keep(job, plan)):
            return
        changed = final > job.planned_final + self._tol(job)
        due = at_rest or job.force_replan or since >= self._every
        if k_last - job.last_fail < self._min_gap and not at_rest:
            return  # a replan just failed: the plan in force stays (it ends at rest)
        if due or (changed and since >= self._min_gap):
            self._replan(job, plan, k_last, state, target)

    def _window(self, job: _Job, s: float) -> tuple[float, float]:
        """The look-ahead window from s (path units) and how far a plan in force may look
        ahead before a replan is due (`REPLAN_KEEP`). The window is `horizon_len`
        (horizon_s at the nominal top feed), shorter where the job's segment feeds cap the
        feed below the top feed over all of it: horizon_s at the highest capped feed there,
        and at least three braking distances from it (DESIGN.md: W >= 3 braking distances
        lost no time). Both in the nominal time frame (the cap over the override's time
        scale f), so that, like `horizon_len`, the window does not change with the
        override. Why: a G-code feed of 100 mm/s on the three-drive winder made 9355 mm
        windows, 93 s of motion and ~2000 LP nodes; their cold LPs took up to 8.6 s,
        longer than any replan's lead (bench/long_program.py)."""
        cap = job.geo.feed_cap(self.override)
        if cap is None:
            return self.horizon_len, self._keep
        lo = max(int(np.searchsorted(cap.s_breaks, s, side="right")) - 1, 0)
        hi = max(int(np.searchsorted(cap.s_breaks, s + self.horizon_len)), lo + 1)
        v_top = float(np.max(cap.values[lo:hi])) / min(self.override, 1.0)
        if not v_top < self._top_feed:
            return self.horizon_len, self._keep
        brake = braking_distance(self.limits, self.path_scale, v_top)
        window = min(self.horizon_len, max(self.horizon_s * v_top, 3.0 * brake))
        return window, max(REPLAN_KEEP * window, REPLAN_KEEP_BRAKING * brake)

    def _window_end(self, job: _Job, s: float, final: float) -> float:
        """Where a plan from s ends (path units): s plus `_window`, at most `final`."""
        return min(final, s + self._window(job, s)[0])

    def _plan_keep(self, job: _Job, plan: CommittedPlan) -> float:
        """`_window`'s keep at the start of `plan`'s stretch (memoized per plan)."""
        if job.keep_memo is None or job.keep_memo[0] is not plan:
            job.keep_memo = (plan, self._window(job, float(plan.profile.at(
                np.array([0.0]))[0, 0]))[1])
        return job.keep_memo[1]

    def _first_plan(self, job: _Job) -> None:
        path = job.geo.path()
        assert path is not None
        target = self._window_end(job, 0.0, job.geo.final_length)
        job.plan = rest_plan(path, 0.0, 0)
        if target > self._tol(job) and not self._commit(job, PathState(0.0), target, 0):
            self._fault_job(job, f"planning: no valid plan from the start of job {job.id!r}")
            job.stop, job.stop_request = "fault", None

    def _begin_stop(self, job: _Job, kind: str) -> None:
        """Replace the plan with the shortest stop within the limits (from the last
        published sample); the current plan, which ends at rest, is the fallback."""
        plan = job.plan
        assert plan is not None
        job.pending = None  # a stop replaces the replan under way too
        if self._ahead_fallback in (self.stop_planner, self.stop_search_planner):
            self._planner_free()
        job.stop = kind
        if kind == "hold":
            job.hold = True
        k_last = job.k - 1
        if k_last < 0:
            job.plan = rest_plan(plan.path, 0.0, 0)
            return
        state = plan.state(k_last, self.dt)
        if k_last >= plan.k_end:
            job.plan = rest_plan(plan.path, plan.s_end, k_last)
            return
        full = self.limits.scaled(self.margin)
        stop = None
        retimed, s_max = None, plan.s_end
        if kind != "override" and self.realtime and self.warp_stops:
            # the plan in force re-timed to rest: no planner call (the shortest-stop search
            # below took up to 16 s from hard states, far longer than the real-time
            # buffer). Taken where it stops within the braking distance's rough guess;
            # else (a plan accelerating hard, which a re-timing can only stretch) the
            # search looks for a shorter stop, and the re-timed one stays if it finds none
            tangent = plan.path.eval_s(np.array([state.s]), order=1)[1, 0]
            found = self._retimed(plan, k_last, job.tail, 0.0,
                                  stop_ramps(state.v, full, tangent), kind)
            if found is not None:
                retimed, s_max = found[0], found[0].s_end
                if retimed.s_end - state.s <= stop_reach(state, full, tangent):
                    stop = retimed
        if kind == "override":
            # slow down with the new acceleration and jerk (full feed limits), so that the
            # state soon fits the new limits and the new plan can take over mid-motion
            f = min(self.override, 1.0)
            gentle = AxisLimits(full.vmax, full.amax * f * f, full.jmax * f**3)
            base = PlanRequest(plan.path, gentle, state, plan.s_end, 0.0, None, self.dt)
            stop = shortest_stop(self.stop_planner, base, k_last, job.tail, self.limits,
                                 plan.s_end, iterations=6)
        if stop is None:
            base = PlanRequest(plan.path, full, state, plan.s_end, 0.0, None, self.dt)
            # trials that fail fast first; the full stop planner if none succeeds (a
            # state beyond the limits, during an override's transition)
            # (with a re-timed stop to keep, only the trials that fail fast: the full stop
            # planner's failing trials from hard states take seconds each)
            searchers = (self.stop_search_planner,) if retimed is not None else (
                self.stop_search_planner, self.stop_planner)
            for planner in dict.fromkeys(searchers):
                stop = shortest_stop(planner, base, k_last, job.tail, self.limits, s_max)
                if stop is not None:
                    break
            if stop is None:
                stop = retimed
        if stop is not None:
            job.plan = stop
            job.stop_in_force = True
            self.plan_ms = stop.compute_s * 1e3
        log.info("stop (%s) job=%s k=%d from s=%.6g v=%.6g: rest at s=%.6g, k=%d", kind,
                 job.id, k_last, state.s, state.v, job.plan.s_end, job.plan.k_end)

    # --- commands ---------------------------------------------------------------------
    def command(self, cmd: Command) -> CommandReply:
        """Apply hold / resume / override / abort / reset (effects at the next batch). Every
        command is listed in the next batch's `commands` field, for replay."""
        self._commands.append((cmd.verb, cmd.value, len(self._applied)))
        return self._apply_command(cmd)

    def _apply_command(self, cmd: Command) -> CommandReply:
        job = self._active
        if cmd.verb == "override":
            assert cmd.value is not None
            if job is not None and not job.override_pending:
                job.override_from = self.override
            self.override = float(cmd.value)
            self._forget_plans()
            if job is not None:
                job.override_pending = True
            return CommandReply(True)
        if cmd.verb == "reset":
            self.fault = None
            self._job_error = None
            return CommandReply(True)
        if cmd.verb == "hold":
            if job is None:
                return CommandReply(False, "hold: no job is running")
            if not job.hold and job.stop not in ("abort", "fault"):
                job.stop_request = "hold"
                job.hold = True
            return CommandReply(True)
        if cmd.verb == "resume":
            if job is None or not job.hold:
                return CommandReply(False, "resume: not holding")
            if job.stop_request == "hold":
                job.stop_request = None
            job.hold = False
            if job.stop == "hold":
                job.stop = None
            job.force_replan = True
            return CommandReply(True)
        if cmd.verb == "abort":
            if job is not None:
                if job.stop not in ("abort", "fault"):
                    job.stop_request = "abort"
                return CommandReply(True)
            if self._jobs:
                queued = next(iter(self._jobs.values()))
                self._emit("job_finished", queued.id, 0, duration_s=0.0, aborted=True)
                self._drop(queued)
                return CommandReply(True)
            return CommandReply(False, "abort: no job")
        return CommandReply(False, f"verb: unknown command {cmd.verb!r}")

    def fail(self, reason: str) -> None:
        """An internal failure outside planning: stop the active job and fault; if it
        already failed once, drop it (its stop cannot be produced)."""
        job = self._active
        if job is None:
            self.fault = reason
            self._emit("fault", None, self._last_k, reason=reason)
        elif job.fault is None:
            self._fault_job(job, reason)
        else:
            self._emit("job_finished", job.id, max(job.k - 1, 0),
                       duration_s=max(job.k - 1, 0) * self.dt, aborted=True)
            self._drop(job)

    # --- status -----------------------------------------------------------------------
    def status(self) -> Status:
        """The state as of the last produced sample; also recounts `buffered` exactly."""
        job = self._active
        name = self.planner.name
        if job is None:
            state = "fault" if self.fault else "idle"
            queued = sum(j.geo.nsegments + j.order.waiting for j in self._jobs.values())
            head = next(iter(self._jobs), None)
            self._buffered = self._count_buffered(None, 0.0)
            return Status(state, head or self._last_job, self._last_k, queued, 0.0,
                          self.override, name, self.plan_ms, self.fault or self._job_error,
                          **self._flow())
        if self.fault or job.fault:
            state = "fault"
        elif job.hold:
            state = "holding"
        elif job.starved:
            state = "starved"
        else:
            state = "running"
        k_last = max(job.k - 1, 0)
        s_now = job.plan.state(k_last, self.dt).s if job.plan is not None else 0.0
        ends = job.geo.segment_ends_s()
        queued = int(np.sum(ends > s_now + self._tol(job))) + job.order.waiting
        queued += sum(j.geo.nsegments + j.order.waiting for j in self._jobs.values()
                      if j is not job)
        horizon = job.plan.remaining_s(k_last, self.dt) if job.plan is not None else 0.0
        complete = self._plan_complete(job)
        self._buffered = self._count_buffered(job, s_now)
        return Status(state, job.id, k_last, queued, horizon, self.override, name,
                      self.plan_ms, self.fault or job.fault, **self._flow(),
                      plan_complete=complete, remaining_s=horizon if complete else None)

    def _plan_complete(self, job: _Job) -> bool:
        """The committed plan runs to the end of the job and no command waits to change it
        (module docstring, "Time left")."""
        if job.plan is None or job.stop_request is not None or job.pending is not None:
            return False
        if job.stop in ("abort", "fault"):
            return True
        return not job.override_pending and not job.force_replan and self._ending(job)

    def _flow(self) -> dict:
        """The flow-control fields of the status (PROTOCOL.md "Status")."""
        rec = self._jobs.get(self._receiving) if self._receiving is not None else None
        return {"receiving": None if rec is None else rec.id,
                "next_seq": None if rec is None else rec.order.expected,
                "buffered_points": self._buffered[0], "accepting": not self.full,
                "fallbacks": self.fallbacks}

    @property
    def full(self) -> bool:
        """True while the buffer is at a cap (service.max_buffered_points / _bytes)."""
        svc = self.config.service
        return (self._buffered[0] >= svc.max_buffered_points
                or self._buffered[1] >= svc.max_buffered_bytes)

    @property
    def active_job(self) -> str | None:
        return self._active.id if self._active is not None else None

    @property
    def busy(self) -> bool:
        """True while a job is active or queued."""
        return self._active is not None or bool(self._jobs)

    # --- bookkeeping ------------------------------------------------------------------
    def _emit(self, etype: str, job: str | None, k: int, **extra) -> Event:
        event = Event(etype, job, int(k), extra)
        self._events.append(event)
        return event

    def _reject(self, job: str | None, seq: int | None, reason: str, **extra) -> Event:
        k = self._active.k - 1 if self._active is not None and job == self._active.id else 0
        return self._emit("rejected", job, max(k, 0), seq=seq, reason=reason, **extra)

    def _seq_fault(self, job: _Job, reason: str) -> None:
        """A seq gap that timed out: the job ends at the end of what it has (see the
        module docstring, "Faults"); not latched."""
        log.error("fault job=%s: %s", job.id, reason)
        k = max(job.k - 1, 0)
        self._emit("rejected", job.id, k, seq=job.order.expected, reason=reason)
        self._emit("fault", job.id, k, reason=reason)
        job.fault = self._job_error = reason
        job.order.close()
        if job is self._active:
            job.geo.truncate()
        else:
            self._emit("job_finished", job.id, 0, duration_s=0.0, aborted=True)
            self._drop(job)

    def _fault_job(self, job: _Job, reason: str) -> None:
        """A latched fault: the active job stops along the path, a queued one is dropped."""
        log.error("fault job=%s: %s", job.id, reason)
        k = max(job.k - 1, 0)
        self._emit("fault", job.id, k, reason=reason)
        self.fault = reason
        job.fault = reason
        if job is self._active:
            job.stop_request = "fault"
            job.hold = False
        else:
            self._emit("job_finished", job.id, 0, duration_s=0.0, aborted=True)
            self._drop(job)

    def _finish(self, job: _Job, aborted: bool) -> None:
        extra = {"aborted": True} if aborted else {}
        extra["fallbacks"] = self.fallbacks - job.fallbacks_at_start
        extra["handovers"] = self.handovers - job.handovers_at_start
        extra["late_replans"] = self.late_replans - job.late_at_start
        self._emit("job_finished", job.id, job.k - 1 if job.k else 0,
                   duration_s=max(job.k - 1, 0) * self.dt, **extra)
        self._drop(job)

    def _forget_plans(self) -> None:
        """Tell planners that keep their last plan (the LP's seams) that it is void. The
        worker's planners are told through the executor, after the replan under way and
        before any later one (it runs its tasks in order), so that a command never waits
        for the worker here (an override's bridge, `_commit_command`)."""
        worker = [p for p in (self.planner, self._ahead_fallback)
                  if callable(getattr(p, "forget", None))]
        if worker:
            self._inflight = self.executor.submit(_forget_all, worker)
        if self.stop_planner not in (self.planner, self._ahead_fallback):
            forget = getattr(self.stop_planner, "forget", None)
            if callable(forget):
                forget()

    def _drop(self, job: _Job, outcome: str = "has already finished") -> None:
        if self._active is job:
            self._forget_plans()
        self._jobs.pop(job.id, None)
        self._done[job.id] = outcome
        while len(self._done) > MAX_DONE:
            self._done.popitem(last=False)
        if self._active is job:
            self._active = None


def _fmt(point: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.9g}" for x in point) + "]"


def stop_ramps(v: float, limits: AxisLimits, tangent: np.ndarray
               ) -> list[tuple[float, float]]:
    """(duration, of which at constant r') s of the rate ramps a stop from path speed v
    tries (`STOP_STRETCH`): the S-curve of r from 1 to 0 with |r'| <= A / v, |r''| <= J / v,
    A and J the path acceleration and jerk the axes allow along `tangent` (dx/ds per
    axis), stretched."""
    v = max(v, 1e-9)
    acc, jerk = _along(limits, tangent)
    r1, r2 = acc / v, jerk / v
    if r1 * r1 >= r2:  # r' never reaches r1: two phases of r'' = -/+ r2
        edge, flat = math.sqrt(1.0 / r2), 0.0
    else:
        edge, flat = r1 / r2, 1.0 / r1 - r1 / r2
    ramp = 2.0 * edge + flat
    stretch = max(1.0, STOP_RAMP_MIN_S / ramp)
    return [(f * stretch * ramp, f * stretch * flat) for f in STOP_STRETCH]


def _along(limits: AxisLimits, tangent: np.ndarray) -> tuple[float, float]:
    """The path acceleration and jerk the axes allow along `tangent` (dx/ds per axis)."""
    along = np.maximum(np.abs(tangent), 1e-12)
    return float(np.min(limits.amax / along)), float(np.min(limits.jmax / along))


def stop_reach(state: PathState, limits: AxisLimits, tangent: np.ndarray) -> float:
    """A rough guess of the braking distance from `state` (path units) along `tangent`:
    about twice the S-curve's from a cruise, more from an accelerating state (the
    shortest-stop search's first guess, `plans.shortest_stop`, with the tangent's limits)."""
    return braking_guess(state.v, state.a, *_along(limits, tangent))


def braking_distance(limits: AxisLimits, path_scale: np.ndarray,
                     v: float | None = None) -> float:
    """S-curve braking distance (path units) from the feed v (default: the nominal top
    feed ||vmax path_scale||) to rest at the smallest path-level acceleration and jerk
    (min over the axes of amax path_scale, jmax path_scale). From the top feed the same at
    any override: the override scales v, a, j by f, f^2, f^3, which leaves it unchanged."""
    if v is None:
        v = float(np.linalg.norm(limits.vmax * path_scale))
    return s_curve_braking_distance(v, float(np.min(limits.amax * path_scale)),
                                    float(np.min(limits.jmax * path_scale)))


def _forget_all(planners: list) -> None:
    """Each planner's `forget()` (an executor task of `Engine._forget_plans`)."""
    for planner in planners:
        planner.forget()


def horizon_length(limits: AxisLimits, path_scale: np.ndarray, horizon_s: float) -> float:
    """Look-ahead window length (path units): horizon_s at the nominal top feed, or three
    S-curve braking distances from it at the smallest path-level limits, whichever is
    larger (DESIGN.md: W >= 3 braking distances lost no time)."""
    v = float(np.linalg.norm(limits.vmax * path_scale))
    return max(horizon_s * v, 3.0 * braking_distance(limits, path_scale))
