"""A replan computed ahead that is late (real time): dropped, the plan in force goes on.

The service gives the engine a budget per take-over (`Engine.takeover_budget`: until the
batch of the take-over must be published). A replan not done within it is dropped: the
plan in force (checked, at rest at its window's end) keeps producing samples, so the
machine slows down but never waits for a batch; the batch lists the dropped take-over in
its `dropped` field, and a replay that drops it too reproduces the stream bit for bit.
"""

from __future__ import annotations

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from lookahead.config import default_config
from lookahead.protocol import Command, ProtocolError, SetpointBatch, _pack, _unpack
from lookahead.stream.engine import LATE_MOVING_TRIES, Engine
from lookahead.stream.planners import make_planner
from lookahead_clients.replay import batch_inputs
from test_stream_ahead import (
    DEADLOCK_S,
    GatedPlanner,
    checked,
    job_segments,
    run_to_end,
    run_until_gated,
)

#: batches produced while the worker stays blocked after the first drop: 4 s of samples,
#: past the rest point of the plan in force (a window of a few seconds)
BLOCKED_BATCHES = 400


def late_run(method: str) -> tuple[Engine, list[SetpointBatch], GatedPlanner, int]:
    """A real-time engine whose worker blocks from its first replan on, with a zero
    budget: every take-over while blocked is dropped. The gate opens after
    BLOCKED_BATCHES batches, then the budget is unlimited and the job runs to its end.
    Returns the engine, its batches, the planner and how many batches came while blocked."""
    cfg = default_config()
    planner = GatedPlanner(method)
    pool = ThreadPoolExecutor(max_workers=1)
    engine, batches = run_until_gated(cfg, planner, pool)
    engine.takeover_budget = lambda k: 0.0
    for _ in range(BLOCKED_BATCHES):
        batch = engine.next_batch()
        assert batch is not None, "the engine gave no batch while its replan was late"
        batches.append(batch)
    assert not planner.gate.is_set()
    n_blocked = len(batches)
    planner.gate.set()
    engine.takeover_budget = None
    batches += run_to_end(engine)
    pool.shutdown()
    return engine, batches, planner, n_blocked


@pytest.fixture(scope="module", params=["heuristic", "lp"])
def late(request) -> tuple[Engine, list[SetpointBatch], GatedPlanner, int]:
    return late_run(request.param)


def test_a_late_replan_is_dropped_and_the_machine_comes_to_rest_on_the_plan_in_force(
        late) -> None:
    engine, batches, _, n_blocked = late
    cfg = default_config()
    pos = checked(cfg, batches)  # contiguous samples, within every limit
    dropped = [(b.k0, k) for b in batches for k in b.dropped]
    assert dropped and engine.late_replans == len(dropped)
    k0, k_at = dropped[0]
    assert k0 == k_at + 1  # dropped when its take-over was due
    # while the worker stayed blocked, the plan in force came to rest and rest samples
    # kept coming (the last 0.5 s of the blocked stretch stand still)
    still = np.vstack([b.pos for b in batches[:n_blocked]])[-500:]
    assert np.all(still == still[0])
    moving = np.vstack([b.pos for b in batches[:n_blocked] if b.k0 >= k_at])
    assert np.ptp(moving, axis=0).max() > 1.0  # ... after moving on the plan in force
    assert engine.replan_failures == 0 and engine.fallbacks == 0
    assert batches[-1].final
    assert pos.shape[0] == batches[-1].k0 + batches[-1].n


def test_job_finished_counts_the_dropped_replans(late) -> None:
    engine, _, _, _ = late
    finished = [e for e in engine.drain_events() if e.type == "job_finished"]
    assert finished and finished[-1].extra["late_replans"] == engine.late_replans > 0


def replay_batches(batches: list[SetpointBatch], method: str, drops: bool
                   ) -> list[SetpointBatch]:
    """The recorded batches replayed into a fresh real-time engine that computes at once
    (segments at their recorded `applied` places, the recorded drops if `drops`), until
    it has no batch."""
    engine = Engine(default_config(), make_planner(method), realtime=True)
    segments = {(s.job, s.seq): s for s in job_segments()}
    out = []
    for want in batches:
        for item in batch_inputs(want):
            assert not isinstance(item, Command)
            engine.submit(segments[item])
        if drops:
            for k_at in want.dropped:
                engine.drop_replan(want.job, k_at)
        for _ in range(1000):
            got = engine.next_batch()
            if got is not None:
                break
        if got is None:
            break  # (a replay that took other plans may finish sooner)
        out.append(got)
    return out


@pytest.mark.parametrize("drops", [True, False])
def test_a_replay_that_drops_the_recorded_take_overs_is_bit_identical(late, drops) -> None:
    _, batches, planner, _ = late
    recorded = [SetpointBatch.decode(b.encode()) for b in batches]  # through the wire
    assert any(b.dropped for b in recorded)
    method = "lp" if planner.name.startswith("lp") else "heuristic"
    replayed = replay_batches(recorded, method, drops)
    same = len(replayed) == len(recorded) and all(
        g.k0 == w.k0 and g.n == w.n and np.array_equal(g.pos, w.pos)
        and np.array_equal(g.vel, w.vel) and np.array_equal(g.acc, w.acc)
        for g, w in zip(replayed, recorded, strict=False))
    # without the drops the replay takes over where the service did not: the streams part
    assert same == drops
    if drops:
        assert [g.dropped for g in replayed] == [w.dropped for w in recorded]


def test_a_replan_done_within_its_budget_takes_over() -> None:
    """A positive budget: the engine waits for the worker (here a replan that takes
    ~0.1 s) and no take-over is dropped."""
    cfg = default_config()
    planner = GatedPlanner("heuristic")
    with ThreadPoolExecutor(max_workers=1) as pool:
        engine, batches = run_until_gated(cfg, planner, pool)
        engine.takeover_budget = lambda k: DEADLOCK_S / 2
        opener = threading.Timer(0.1, planner.gate.set)  # while the engine waits for it
        opener.start()
        t0 = time.monotonic()
        batches += run_to_end(engine)
        opener.join()
    assert time.monotonic() - t0 < DEADLOCK_S / 2  # it took over once done, not at budget end
    assert engine.late_replans == 0 and not any(b.dropped for b in batches)
    assert engine.takeover_waits >= 1 and engine.replans >= 2
    checked(cfg, batches)


def test_the_dropped_field_on_the_wire() -> None:
    b = SetpointBatch("j", 0, 5, 0.001, ("X",), np.zeros((1, 1)), np.zeros((1, 1)),
                      np.zeros((1, 1)), False)
    assert "dropped" not in _unpack(b.encode(), 1 << 20)  # old readers see the same batch
    assert SetpointBatch.decode(b.encode()).dropped == ()
    msg = _unpack(b.encode(), 1 << 20)
    msg["dropped"] = [4, 2]
    assert SetpointBatch.decode(_pack(msg)).dropped == (4, 2)
    for bad in ("4", [-1], [1.5]):
        msg["dropped"] = bad
        with pytest.raises(ProtocolError) as err:
            SetpointBatch.decode(_pack(msg))
        assert err.value.field == "dropped"


def test_the_services_budget_ends_before_the_take_over_batch_is_due() -> None:
    """The real-time service gives the engine a budget per take-over: until the batch
    starting at the take-over sample must be published, less TAKEOVER_MARGIN_S; none
    before the job's clock has started, and no budget at all in fast mode."""
    from lookahead.service import TAKEOVER_MARGIN_S, PlannerService

    cfg = default_config()
    assert PlannerService(cfg, fast=True).engine.takeover_budget is None
    svc = PlannerService(cfg)
    assert svc.engine.takeover_budget == svc._takeover_budget
    for seg in job_segments():
        svc.engine.submit(seg)
    first = svc.engine.next_batch()
    assert first is not None and first.k0 == 0
    assert svc._takeover_budget(1000) is None  # the pacer has not published batch 0 yet
    now = time.monotonic()
    svc.pacer.start(now)  # what the pacer thread does with a job's first batch
    svc._clock_job = first.job
    budget = svc._takeover_budget(1000)
    assert budget is not None
    expected = svc.pacer.publish_at(1000) - now - TAKEOVER_MARGIN_S
    assert expected - 0.5 < budget <= expected  # (the clock moved on between the calls)
    assert budget == pytest.approx(1000 * cfg.machine.dt - TAKEOVER_MARGIN_S, abs=0.5)
    svc._clock_job = "another job"
    assert svc._takeover_budget(1000) is None
    svc._planning.shutdown()


class SlowPlanner:
    """A real planner whose calls after the first take `delay` seconds longer."""

    def __init__(self, method: str, delay: float) -> None:
        self.inner = make_planner(method)
        self.name = self.inner.name
        self.delay = delay
        self.calls = 0

    def plan(self, request):
        self.calls += 1
        if self.calls > 1:
            time.sleep(self.delay)
        return self.inner.plan(request)

    def __getattr__(self, name: str):
        return getattr(self.inner, name)


#: a replan's extra time and each take-over's budget (s): every replan is late, the
#: one-batch-at-a-time engine waits `SLOW_BUDGET_S` at each take-over and no longer
SLOW_REPLAN_S = 0.25
SLOW_BUDGET_S = 0.08


@pytest.mark.parametrize("method", ["heuristic", "lp"])
def test_a_replan_slower_than_the_restart_is_not_dropped_forever(method) -> None:
    """Every replan takes longer than any take-over's budget. A dropped replan's
    computation goes on, and the restart from the rest point it leaves the machine at
    reuses it (it asks for the same plan): the job goes on after a few drops. Before, each
    restart queued a new computation behind the dropped one, which could never be done
    within the budget: dropped forever, the machine at rest for good."""
    cfg = default_config()
    planner = SlowPlanner(method, SLOW_REPLAN_S)
    with ThreadPoolExecutor(max_workers=1) as pool:
        engine = Engine(cfg, planner, realtime=True, executor=pool)
        for seg in job_segments():
            engine.submit(seg)
        engine.takeover_budget = lambda k: SLOW_BUDGET_S
        batches = run_to_end(engine, limit=20000)
    pos = checked(cfg, batches)
    assert pos.shape[0] == batches[-1].k0 + batches[-1].n
    assert engine.late_replans > 0 and engine.replans >= 2
    # per take-over: LATE_MOVING_TRIES moving tries, then restarts from rest while at
    # most two computations finish (the dropped one and the restart's, which the later
    # restarts reuse: they call no planner)
    take_overs = engine.replans - 1
    per = LATE_MOVING_TRIES + math.ceil(2 * SLOW_REPLAN_S / SLOW_BUDGET_S)
    assert engine.late_replans <= per * take_overs
    assert planner.calls <= engine.replans + engine.late_replans  # not one per restart
    recorded = [SetpointBatch.decode(b.encode()) for b in batches]
    replayed = replay_batches(recorded, method, drops=True)
    assert len(replayed) == len(recorded) and all(
        g.k0 == w.k0 and np.array_equal(g.pos, w.pos) for g, w in zip(replayed, recorded,
                                                                      strict=True))
