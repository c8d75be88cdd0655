"""The planner service on Zenoh (PROTOCOL.md): a thin wrapper around `stream.engine.Engine`.

Threads: a drain thread empties the NS/segments FifoChannel into a queue of payloads; zenoh
calls the NS/cmd/* and NS/status queryables on its own threads (commands are handed to
the main loop and answered once applied); the main loop (`run`, the caller's thread) owns
the engine: it decodes segments, applies commands, publishes batches (real-time: paced by
the wall clock, `lead_s` ahead of due time; fast: as fast as possible), events and status.

What a client sees is consistent with the setpoints already published: in real-time mode
the engine produces up to MAX_AHEAD_S ahead of publication, so events about motion
(`job_started`, `starved`, `job_finished`) wait until the batch holding their sample k is
published, and the status reports the last published sample (its `k`, `horizon_s`,
`remaining_s` and a `running` job whose last batches are still buffered: the samples
produced but not yet published are added to the engine's times, which start at the last
produced sample). The status answer (queryable) is
refreshed whenever events are released, after commands, after segments are taken in and
at status_hz.
"""

from __future__ import annotations

import collections
import logging
import math
import queue
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import msgpack

from lookahead.bus import (
    SETPOINT_CACHE,
    open_session,
    poll_fifo,
    recovering_subscriber,
    reliable_publisher,
)
from lookahead.config import Config
from lookahead.planning.base import Planner
from lookahead.protocol import (
    JOB_ID_RE,
    MAX_PAYLOAD_BYTES,
    Command,
    CommandReply,
    Event,
    ProtocolError,
    Segment,
    SetpointBatch,
    Status,
    key,
)
from lookahead.stalls import StallProbe
from lookahead.stream.engine import Engine
from lookahead.stream.pacing import Pacer
from lookahead.stream.planners import make_planner

log = logging.getLogger("lookahead.service")

#: segments buffered by zenoh before the drain thread takes them
FIFO_CAPACITY = 4096
#: undecoded segment payloads the drain thread hands to the main loop at most (count,
#: bytes); beyond, it waits, the FifoChannel fills and zenoh holds the publisher back
#: (blocking congestion control). 1024 x 200-point segments are ~3.7 MB.
INCOMING_MAX = 1024
INCOMING_MAX_BYTES = 32 * 1024 * 1024
#: longest sleep of the main loop (s)
MAX_SLEEP_S = 0.01
#: longest the main loop spends taking in segments at a time (s): a burst of thousands
#: must not hold up batches, status or commands (real-time mode produces MIN_AHEAD_S plus
#: 1.5 x the slowest replan ahead, >= 50 ms); longer passes take a resend and the segments
#: behind it in one go (recovery, bench/delivery_bench.py)
TAKE_IN_MAX_S = 0.05
#: fast mode: batches published between two looks at commands and status
FAST_BURST = 50
#: real-time mode: longest the main loop spends producing batches at a time (s). It used to
#: produce one batch (10 ms of motion) per loop, after a take-in pass of up to
#: TAKE_IN_MAX_S: while the 100k-line program's segments came in after its start, the
#: service fell 0.89 s behind real time (bench/long_program.py --realtime, stop 25)
PRODUCE_MAX_S = 0.05
#: real-time mode: produce at least this far ahead of publication, plus 1.5 x the longest
#: batch computation seen (a replan, a stop or a job's first plan), at most
#: MAX_AHEAD_S (s)
MIN_AHEAD_S = 0.05
MAX_AHEAD_S = 1.0
#: real time: a replan computed ahead that is not done this long (s) before the batch of
#: its take-over must be published is dropped, and the plan in force goes on
#: (`Engine.takeover_budget`). It is what producing and handing over that batch takes after
#: the decision: sampling a 10-sample batch takes < 1 ms; the rest covers the GIL switches
#: (5 ms each) while the worker thread plans
TAKEOVER_MARGIN_S = 0.02
#: how long a command query waits for the main loop (s)
COMMAND_TIMEOUT_S = 5.0
#: shutdown: longest wait for the stop to finish (s)
SHUTDOWN_TIMEOUT_S = 30.0
#: events published only once the samples they are about are published
MOTION_EVENTS = ("job_started", "starved", "job_finished")


@dataclass
class _PendingCommand:
    command: Command
    done: threading.Event = field(default_factory=threading.Event)
    reply: CommandReply | None = None


@dataclass
class ServiceStats:
    """Counters of one run (for the benchmark and the logs)."""

    segments: int = 0
    rejected: int = 0
    batches: int = 0
    samples: int = 0
    max_late_s: float = 0.0
    first_segment_s: float | None = None
    first_batch_s: float | None = None
    #: delivery: segments turned away while the buffer was full, `missing` events, and the
    #: most the engine buffered (points, bytes) and the drain queue held (payloads, bytes)
    refused_full: int = 0
    missing: int = 0
    max_buffered_points: int = 0
    max_buffered_bytes: int = 0
    max_incoming: int = 0
    max_incoming_bytes: int = 0


class PlannerService:
    """`lookahead serve`: open(), run() until request_shutdown(), close()."""

    def __init__(self, config: Config, fast: bool = False, planner: Planner | None = None
                 ) -> None:
        self.config = config
        self.fast = fast
        self.ns = config.ns
        # real-time mode: replans are computed in a worker thread while the plan in force
        # keeps producing samples (stream/ahead.py); fast mode computes them at once
        self._planning = (None if fast else
                          ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner"))
        self.engine = Engine(config, planner or make_planner(config.planner.method),
                             realtime=not fast, executor=self._planning)
        self.pacer = Pacer(config.machine.dt, config.service.lead_s)
        self._clock_job: str | None = None  # the job whose first batch started the pacer
        # real time: jobs whose clock may start (their first batches are buffered far
        # enough ahead, see _produce_paced); guarded by _out_cv
        self._primed_jobs: set[str] = set()
        if not fast:
            self.engine.takeover_budget = self._takeover_budget
        self.stats = ServiceStats()
        self._incoming: queue.Queue[bytes] = queue.Queue()
        self._incoming_bytes = 0  # bytes of the payloads in _incoming
        self._incoming_cv = threading.Condition()
        self._filled_gap = False  # the payloads taken in since the last pass filled a gap
        self._commands: queue.Queue[_PendingCommand] = queue.Queue()
        self._shutdown = threading.Event()
        self._drain_stop = threading.Event()
        self._status_payload = self.engine.status().encode()
        self._session: Any = None
        self._decls: list[Any] = []
        self._drain_thread: threading.Thread | None = None
        self._pace_thread: threading.Thread | None = None
        self._out: collections.deque[SetpointBatch] = collections.deque()
        self._out_cv = threading.Condition()
        self._out_samples = 0
        self._max_compute_s = 0.0
        self._next_poll = 0.0  # real time: when _produce_paced next looks (monotonic s)
        self._late_logged = -math.inf  # when a late batch was last logged (monotonic s)
        self._stalls = StallProbe()  # what held a late batch up (in its WARNING)
        self._job_end_due: float | None = None
        self._held: list[Event] = []  # events waiting for their samples to be published

    # --- bus ------------------------------------------------------------------------
    def open(self) -> None:
        self._session = session = open_session(self.config.zenoh)
        self._pub_setpoints = reliable_publisher(session, key(self.ns, "setpoints"),
                                                 cache=SETPOINT_CACHE)
        self._pub_events = reliable_publisher(session, key(self.ns, "events"))
        self._pub_status = session.declare_publisher(key(self.ns, "status"))
        self._sub = recovering_subscriber(session, key(self.ns, "segments"), FIFO_CAPACITY,
                                          on_miss=self._segments_lost)
        self._decls += [self._pub_setpoints, self._pub_events, self._pub_status]
        self._decls.append(session.declare_queryable(key(self.ns, "status"), self._on_status))
        self._decls.append(session.declare_queryable(key(self.ns, "cmd", "*"),
                                                     self._on_command))
        self._token = session.liveliness().declare_token(key(self.ns, "alive", "planner"))
        self._drain_thread = threading.Thread(target=self._drain, name="segments-drain",
                                              daemon=True)
        self._drain_thread.start()
        if not self.fast:
            self._pace_thread = threading.Thread(target=self._pace, name="pacer", daemon=True)
            self._pace_thread.start()
            self._stalls.start()
        log.info("serving ns=%s planner=%s mode=%s listen=%s connect=%s", self.ns,
                 self.config.planner.method, "fast" if self.fast else "real-time",
                 list(self.config.zenoh.listen), list(self.config.zenoh.connect))

    def close(self) -> None:
        self._stalls.stop()
        self._drain_stop.set()
        with self._out_cv:
            self._out_cv.notify_all()
        for thread in (self._drain_thread, self._pace_thread):
            if thread is not None:
                thread.join(timeout=2.0)
        if self._planning is not None:
            self._planning.shutdown(wait=False, cancel_futures=True)
        if self._session is None:
            return
        for decl in [*self._decls, self._sub, self._token]:
            try:
                decl.undeclare()
            except Exception:  # already gone with a closing session
                log.debug("undeclare failed", exc_info=True)
        self._session.close()
        self._session = None

    def _segments_lost(self, n: int) -> None:
        """The bus lost `n` segments for good (gone from the publisher's cache): the
        `missing` event asks for them again (PROTOCOL.md "Delivery")."""
        log.warning("segments: %d lost on the bus (no longer in the publisher's cache); "
                    "they will be asked for with `missing`", n)

    def _drain(self) -> None:
        """FifoChannel -> queue of payloads (at most INCOMING_MAX / _BYTES), until close()."""
        poll_fifo(self._sub, lambda sample: self._enqueue(sample.payload.to_bytes()),
                  self._drain_stop)

    def _enqueue(self, payload: bytes) -> None:
        with self._incoming_cv:
            while ((self._incoming.qsize() >= INCOMING_MAX
                    or self._incoming_bytes + len(payload) > INCOMING_MAX_BYTES)
                   and self._incoming.qsize() and not self._drain_stop.is_set()):
                self._incoming_cv.wait(0.05)
            self._incoming.put(payload)
            self._incoming_bytes += len(payload)
            self.stats.max_incoming = max(self.stats.max_incoming, self._incoming.qsize())
            self.stats.max_incoming_bytes = max(self.stats.max_incoming_bytes,
                                                self._incoming_bytes)

    def _dequeued(self, payload: bytes) -> None:
        with self._incoming_cv:
            self._incoming_bytes -= len(payload)
            self._incoming_cv.notify_all()

    def _on_status(self, query: Any) -> None:
        query.reply(query.key_expr, self._status_payload)

    def _on_command(self, query: Any) -> None:
        verb = str(query.key_expr).rsplit("/", 1)[-1]
        payload = query.payload.to_bytes() if query.payload is not None else None
        try:
            cmd = Command.decode(verb, payload)
        except ProtocolError as exc:
            query.reply(query.key_expr, CommandReply(False, str(exc)).encode())
            return
        pending = _PendingCommand(cmd)
        self._commands.put(pending)
        if not pending.done.wait(COMMAND_TIMEOUT_S):
            reply = CommandReply(False, f"{verb}: the service did not answer in time")
        else:
            reply = pending.reply or CommandReply(False, f"{verb}: no reply")
        query.reply(query.key_expr, reply.encode())

    # --- main loop ------------------------------------------------------------------
    def request_shutdown(self) -> None:
        """Stop the running job along the path (abort), then leave `run` (signal-safe)."""
        self._shutdown.set()

    def run(self) -> int:
        """Serve until request_shutdown() and the stop is done; returns an exit code."""
        next_status = 0.0
        deadline: float | None = None
        self._next_poll = 0.0
        while True:
            now = time.monotonic()
            self._take_in(now)
            self._apply_commands()
            if self._shutdown.is_set():
                if deadline is None:
                    deadline = now + SHUTDOWN_TIMEOUT_S
                    if self.engine.active_job is not None:
                        log.info("shutdown: stopping job %s", self.engine.active_job)
                        self.engine.command(Command("abort"))
                if self.engine.active_job is None and self._buffered_s() == 0:
                    break
                if now > deadline:
                    log.error("shutdown: the stop did not finish in %s s", SHUTDOWN_TIMEOUT_S)
                    break
            self.engine.expire_gaps(now)
            self._announce_missing(now)
            produced = self._produce_fast() if self.fast else self._produce_paced(now)
            self._publish_events()
            if now >= next_status:
                self._publish_status()
                next_status = now + 1.0 / self.config.service.status_hz
            if not produced:
                self._sleep(now, next_status)
        self._publish_events(release_all=True)
        self._publish_status()
        log.info("stopped: %d segments, %d rejected, %d batches, %d samples, "
                 "%d replans (%d failed)", self.stats.segments, self.stats.rejected,
                 self.stats.batches, self.stats.samples, self.engine.replans,
                 self.engine.replan_failures)
        return 0

    def _sleep(self, now: float, next_status: float) -> None:
        wake = min(next_status, now + MAX_SLEEP_S)
        if not self.fast:
            wake = min(wake, self._next_poll)
        timeout = wake - time.monotonic()
        if timeout <= 0:
            return
        try:
            payload = self._incoming.get(timeout=timeout)
        except queue.Empty:
            return
        self._dequeued(payload)
        self._handle_payload(payload, time.monotonic())
        self._after_take_in(time.monotonic())

    def _stopping_done(self) -> bool:
        return self._shutdown.is_set() and self.engine.active_job is None

    def _produce_fast(self) -> bool:
        produced = 0
        while produced < FAST_BURST and not self._stopping_done():
            batch = self._next_batch()
            if batch is None:
                break
            self._publish_batch(batch, time.monotonic())
            produced += 1
            self._take_in(time.monotonic())
        return produced > 0

    def _produce_paced(self, now: float) -> bool:
        """Real-time: keep the buffer ahead of publication by the expected compute time,
        producing batches until it is (for at most PRODUCE_MAX_S at a time); the pacer
        thread publishes each batch lead_s before it is due. A job's clock starts only
        once it is primed: that far ahead, at its end, or with nothing more to produce."""
        if now < self._next_poll or self._stopping_done():
            return False
        produced = False
        start = time.monotonic()
        while not produced or time.monotonic() - start < PRODUCE_MAX_S:
            ahead = MIN_AHEAD_S + min(MAX_AHEAD_S, 1.5 * self._max_compute_s)
            if self._buffered_s() >= ahead:
                self._prime()
                self._next_poll = now + self.config.service.batch * self.config.machine.dt
                break
            batch = self._produce_one()
            if batch is None:
                # the engine has nothing now (it waits for segments): start what is buffered
                self._prime()
                self._next_poll = now + self.config.service.batch * self.config.machine.dt
                break
            produced = True
            if batch.final:
                self._prime()
        return produced

    def _prime(self) -> None:
        """Let the clocks of the jobs buffered so far start. Before this, a job's first
        batch (its first plan, up to a second) left the loop with 10 ms buffered: the pacer
        published it at once and the batches after it waited on a take-in pass. The 100k-
        line program underran 2-3 times, up to 20 ms, at its start (stop 31)."""
        with self._out_cv:
            self._primed_jobs.update(b.job for b in self._out if b.k0 == 0)
            self._out_cv.notify_all()

    def _produce_one(self) -> SetpointBatch | None:
        """One batch into the real-time buffer (None if the engine has none now)."""
        t = time.monotonic()
        waits, buffered = self.engine.takeover_waits, self._buffered_s()
        batch = self._next_batch()
        # every computation counts, a job's first batch too: its first plan (the slowest
        # of a job) starts the job's clock when published, so nothing waits on it, but it
        # is the best estimate of the replans that follow right after; without it the lead
        # was 50 ms at a job's start and the real-time demo underran 7-14 times (both
        # planners, quiet 2-core machine) once replans took longer than that
        took = time.monotonic() - t
        self._max_compute_s = max(self._max_compute_s, took)
        if batch is not None and batch.k0 > 0 and took > buffered + self.pacer.lead_s:
            # the buffer ran dry while this batch was computed: the machine waits (not
            # for a job's first batch: the job's clock starts when it is published)
            log.warning("real time: a batch took %.3f s with %.3f s buffered (%s)", took,
                        buffered, "waiting for the replan computed ahead"
                        if self.engine.takeover_waits > waits else "computed at once")
        if batch is None:
            return None
        with self._out_cv:
            self._out.append(batch)
            self._out_samples += batch.n
            self._out_cv.notify_all()
        return batch

    def _takeover_budget(self, k: int) -> float | None:
        """How long (s) the engine may still wait for the replan computed ahead that takes
        over at sample k of the active job: until the batch starting there must be
        published, less TAKEOVER_MARGIN_S (the batches before it are buffered and published
        meanwhile by the pacer thread). None (no limit) until the job's clock has started."""
        if self._clock_job is None or self._clock_job != self.engine.active_job:
            return None
        return self.pacer.publish_at(k) - time.monotonic() - TAKEOVER_MARGIN_S

    def _buffered_s(self) -> float:
        return self._out_samples * self.config.machine.dt

    def _pace(self) -> None:
        """Pacer thread: publish buffered batches at due time - lead_s. A job's clock
        starts when its first batch is taken, once the job is primed (`_prime`), and not
        before the previous job's end."""
        while not self._drain_stop.is_set():
            with self._out_cv:
                while not self._drain_stop.is_set() and not self._startable():
                    self._out_cv.wait(0.1)
                if not self._startable():
                    return
                batch = self._out[0]
                if batch.k0 == 0:
                    self._primed_jobs.discard(batch.job)
            now = time.monotonic()
            if batch.k0 == 0:
                self.pacer.start(max(now, self._job_end_due or now))
                self._clock_job = batch.job
            publish_at = self.pacer.publish_at(batch.k0)
            wait = publish_at - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            now = time.monotonic()
            late = self.pacer.late_s(batch.k0, now)
            self.stats.max_late_s = max(self.stats.max_late_s, late + self.pacer.lead_s)
            if late > 0.0 and now >= self._late_logged + 1.0:  # at most once a second
                self._late_logged = now
                log.warning("real time: batch k0=%d of job %s published %.3f s after its "
                            "first sample was due (since its publish time: %s)", batch.k0,
                            batch.job, late, self._stalls.describe(publish_at))
            self._publish_batch(batch, now)
            if batch.final:
                self._job_end_due = self.pacer.due_s(batch.k0 + batch.n) - self.pacer.lead_s
            with self._out_cv:
                self._out.popleft()
                self._out_samples -= batch.n

    def _startable(self) -> bool:
        """The pacer may take the head batch: a running job's, or a primed job's first
        (call with _out_cv held)."""
        return bool(self._out) and (self._out[0].k0 > 0 or self._out[0].job in self._primed_jobs)

    def _next_batch(self) -> SetpointBatch | None:
        try:
            return self.engine.next_batch()
        except Exception as exc:  # an internal failure must not take the service down
            log.exception("internal error while producing a batch")
            self.engine.fail(f"internal: {exc.__class__.__name__}: {exc}")
            return None

    # --- input ------------------------------------------------------------------------
    def _take_in(self, now: float) -> None:
        taken = False
        start = time.monotonic()
        # the time limit holds while a job runs (its batches must keep coming); before a
        # job starts, everything queued is taken in at once, so that a job whose segments
        # all arrived starts with all of them (cut at 50 ms, the demo's job started with
        # part of its path and underran 5-14 times on the rest's take-in and replans)
        until = start + (TAKE_IN_MAX_S if self.engine.active_job is not None else math.inf)
        while time.monotonic() < until:
            try:
                payload = self._incoming.get_nowait()
            except queue.Empty:
                break
            self._dequeued(payload)
            self._handle_payload(payload, now)
            taken = True
        if taken:
            if self._filled_gap or self.engine.active_job is not None:
                # a pass while a job runs (or one that took a resend and the segments
                # waiting behind it) held up production like a replan, so it counts toward
                # the real-time buffer's lead. Passes before a job starts do not (nothing
                # waits on them). Not counting the passes during a job made the real-time
                # demo underrun 5-14 times: a job starts once its window is covered, and
                # the rest of its segments (tens of ms each with the fits' checks) came in
                # while it ran
                self._max_compute_s = max(self._max_compute_s,
                                          min(time.monotonic() - start, MAX_AHEAD_S))
            self._filled_gap = False
            self._after_take_in(now)

    def _after_take_in(self, now: float) -> None:
        """Segments came in: announce new gaps at once, refresh the status answer
        (`queued`, `next_seq`, `buffered_points` changed)."""
        self._status_payload = self._status().encode()  # also recounts the buffer
        points, nbytes = self.engine.buffered
        self.stats.max_buffered_points = max(self.stats.max_buffered_points, points)
        self.stats.max_buffered_bytes = max(self.stats.max_buffered_bytes, nbytes)
        self._announce_missing(now)

    def _announce_missing(self, now: float) -> None:
        if self.engine.announce_missing(now):
            self._publish_events()

    def _handle_payload(self, payload: bytes, now: float) -> None:
        if self.stats.first_segment_s is None:
            self.stats.first_segment_s = now
        try:
            seg = Segment.decode(payload, axes=self.engine.axes)
        except ProtocolError as exc:
            job, seq = peek_ids(payload)
            self.engine.reject(str(exc), job, seq)
            return
        self.stats.segments += 1
        admission = self.engine.admission(seg)
        self._filled_gap = self._filled_gap or admission == "gap"
        if self.engine.full and admission == "new":
            # full: only a segment that fills a gap is taken (waiting ones sit behind it);
            # this one is turned away, and the publisher sends it again (PROTOCOL.md
            # "Delivery", docs/protocol.md "Delivery and flow control")
            points, nbytes = self.engine.buffered
            svc = self.config.service
            self.stats.refused_full += 1
            self.engine.reject(f"buffer: full ({points} points, {nbytes} bytes received but "
                               f"not executed; caps {svc.max_buffered_points} points, "
                               f"{svc.max_buffered_bytes} bytes): send seq {seg.seq} again "
                               "when the status shows accepting", seg.job, seg.seq,
                               retry=True)
            return
        try:
            self.engine.submit(seg, now)
        except Exception as exc:  # a bug must not take the service down
            log.exception("internal error taking in segment %s/%d", seg.job, seg.seq)
            self.engine.reject(f"internal: {exc.__class__.__name__}: {exc}", seg.job, seg.seq)

    def _apply_commands(self) -> None:
        while True:
            try:
                pending = self._commands.get_nowait()
            except queue.Empty:
                return
            try:
                pending.reply = self.engine.command(pending.command)
            except Exception as exc:
                log.exception("internal error applying %s", pending.command.verb)
                pending.reply = CommandReply(False, f"internal: {exc}")
            log.info("command %s%s -> %s", pending.command.verb,
                     "" if pending.command.value is None else f" {pending.command.value}",
                     "ok" if pending.reply.ok else pending.reply.error)
            self._status_payload = self._status().encode()
            pending.done.set()

    # --- output -----------------------------------------------------------------------
    def _publish_batch(self, batch: SetpointBatch, now: float) -> None:
        self._pub_setpoints.put(batch.encode())
        self.stats.batches += 1
        self.stats.samples += batch.n
        if self.stats.first_batch_s is None:
            self.stats.first_batch_s = now
        if batch.final:
            log.info("final batch job=%s seq=%d k=%d", batch.job, batch.seq,
                     batch.k0 + batch.n - 1)

    def _publish_events(self, release_all: bool = False) -> None:
        self._held += self.engine.drain_events()
        events = self._releasable()
        if release_all:  # shutting down: nothing more will be published
            events, self._held = events + self._held, []
        if events:
            # a client that sees an event and then asks for the status must not get an
            # answer older than the event
            self._status_payload = self._status().encode()
        for event in events:
            if event.type == "rejected":
                self.stats.rejected += 1
            elif event.type == "missing":
                self.stats.missing += 1
            self._pub_events.put(event.encode())
            level = logging.WARNING if event.type in ("rejected", "fault", "starved") \
                else logging.INFO
            extra = " ".join(f"{k}={v!r}" for k, v in event.extra.items())
            log.log(level, "event %s job=%s k=%d %s", event.type, event.job, event.k, extra)

    def _publish_status(self) -> None:
        self._status_payload = self._status().encode()
        self._pub_status.put(self._status_payload)

    def _unpublished(self) -> list[SetpointBatch]:
        with self._out_cv:
            return list(self._out)

    def _releasable(self) -> list[Event]:
        """Held events that may be published now, in order; motion events stay (in order)
        while a batch with a sample <= their k of their job is unpublished."""
        if not self._held:
            return []
        out = self._unpublished()
        ready, keep = [], []
        for event in self._held:
            waits = event.type in MOTION_EVENTS and (
                bool(keep) or any(b.job == event.job and b.k0 <= event.k for b in out))
            (keep if waits else ready).append(event)
        self._held = keep
        return ready

    def _status(self) -> Status:
        """The engine's status as of the last published sample (see the module docstring)."""
        status = self.engine.status()
        out = self._unpublished()
        if not out:
            return status
        head = out[0]
        mine = [b for b in out if b.job == head.job]
        ahead = sum(b.n for b in mine) * self.config.machine.dt
        if status.job == head.job and status.state != "idle":
            remaining = None if status.remaining_s is None else status.remaining_s + ahead
            return replace(status, k=max(head.k0 - 1, 0), horizon_s=status.horizon_s + ahead,
                           remaining_s=remaining)
        # the engine is done with the head job: what is unpublished of it is all there is
        # if its final batch is among it (else it was dropped without one, after a failure)
        complete = mine[-1].final
        return replace(status, state="running", job=head.job, k=max(head.k0 - 1, 0),
                       horizon_s=ahead, error=None, plan_complete=complete,
                       remaining_s=ahead if complete else None)


def peek_ids(payload: bytes) -> tuple[str | None, int | None]:
    """Best-effort (job, seq) of a payload that failed validation, for its `rejected`."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        return None, None
    try:
        msg = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:
        return None, None
    if not isinstance(msg, dict):
        return None, None
    job = msg.get("job")
    seq = msg.get("seq")
    job = job if isinstance(job, str) and JOB_ID_RE.match(job) else None
    seq = seq if isinstance(seq, int) and not isinstance(seq, bool) and seq >= 0 else None
    return job, seq
