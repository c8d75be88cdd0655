"""Real-time mode, without a bus: what clients see (events, status) follows the setpoints
actually published, not the engine, which produces ahead of publication."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from lookahead.protocol import Segment
from lookahead.service import PlannerService
from service_harness import service_config


def test_motion_events_and_status_wait_for_their_samples_to_be_published():
    svc = PlannerService(service_config(), fast=False)  # never opened: no bus needed
    eng, dt = svc.engine, svc.config.machine.dt
    line = np.array([[0.0, 0.0], [60.0, 30.0]])
    eng.submit(Segment("rt", 0, ("X", "C"), "points", True, points=line))
    while not svc._out or not svc._out[-1].final:  # produced, buffered, not yet published
        batch = eng.next_batch()
        if batch is not None:
            svc._out.append(batch)
    total = sum(b.n for b in svc._out)
    svc._held += eng.drain_events()
    assert [e.type for e in svc._held] == ["job_started", "job_finished"]
    assert eng.status().state == "idle"  # the engine is done...
    status = svc._status()  # ...but nothing was published yet
    assert (status.state, status.job, status.k) == ("running", "rt", 0)
    assert status.horizon_s == pytest.approx(total * dt)
    assert svc._releasable() == []
    published = 0
    while svc._out:  # the pacer publishes the batches one by one
        batch = svc._out.popleft()
        published += batch.n
        released = [e.type for e in svc._releasable()]
        if batch.seq == 0:
            assert released == ["job_started"]
        elif batch.final:
            assert released == ["job_finished"]
        else:
            assert released == []
            status = svc._status()
            assert status.k == published - 1 and status.state == "running"
            assert status.horizon_s == pytest.approx((total - published) * dt)
    assert svc._status().state == "idle" and not svc._held


def test_segments_queued_before_a_job_starts_are_all_taken_in_at_once(monkeypatch):
    """Before a job runs, one take-in pass takes everything queued (the time limit holds only
    while a job runs): a job whose segments all arrived starts with its whole path. Cut at
    the limit, the demo's job started with part of its path and underran in real time."""
    import lookahead.service as service_module
    from lookahead_clients.job_source import make_segments

    monkeypatch.setattr(service_module, "TAKE_IN_MAX_S", 0.0)  # any pass would stop at once
    svc = PlannerService(service_config(), fast=False)  # never opened: no bus needed
    t = np.linspace(0.0, 1.0, 600)
    pts = np.column_stack([300.0 * t, 200.0 * t + 10.0 * np.sin(5 * t)])
    segs = make_segments("all-in", ["X", "C"], pts, chunk=100)
    for seg in segs:
        svc._enqueue(seg.encode())
    svc._take_in(0.0)
    assert svc._incoming.empty() and svc.stats.segments == len(segs) == 6
    assert svc.engine.status().queued == len(segs)


def test_a_jobs_clock_starts_only_once_its_first_batches_are_buffered(monkeypatch):
    """The job's first batch (its first plan) must not start the clock with 10 ms buffered:
    the batches after it would wait on the next take-in pass (the 100k-line program underran
    at its start). The pacer takes a first batch only once the job is primed: as far ahead
    as the service keeps the buffer, or at the job's end."""
    import lookahead.service as service_module

    monkeypatch.setattr(service_module, "PRODUCE_MAX_S", 0.0)  # one batch per call
    monkeypatch.setattr(service_module, "MIN_AHEAD_S", 0.3)
    svc = PlannerService(service_config(), fast=False)  # never opened: no bus needed
    t = np.linspace(0.0, 1.0, 400)
    pts = np.column_stack([600.0 * t, 400.0 * t + 20.0 * np.sin(5 * t)])
    svc.engine.submit(Segment("prime", 0, ("X", "C"), "points", True, points=pts))
    calls = 0
    while not svc._startable():
        svc._next_poll = 0.0
        assert svc._produce_paced(time.monotonic()) or svc._out, "nothing was produced"
        with svc._out_cv:
            startable = svc._startable()
        if not startable:
            assert not svc._out[-1].final
        calls += 1
    assert calls > 1  # the first call's single batch did not start the clock
    assert svc._out[0].k0 == 0 and svc._out[0].job == "prime"
    assert svc._buffered_s() >= 0.3 or svc._out[-1].final
    # a short job is primed by its final batch even below the lead
    monkeypatch.setattr(service_module, "MIN_AHEAD_S", 1e6)
    svc2 = PlannerService(service_config(), fast=False)
    svc2.engine.submit(Segment("short", 0, ("X", "C"), "points", True,
                               points=np.array([[0.0, 0.0], [5.0, 3.0]])))
    while not svc2._out or not svc2._out[-1].final:
        assert not svc2._startable()
        svc2._next_poll = 0.0
        svc2._produce_paced(time.monotonic())
    assert svc2._startable()
