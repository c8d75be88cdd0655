"""Real-time mode, without a bus: what clients see (events, status) follows the setpoints
actually published, not the engine, which produces ahead of publication."""

from __future__ import annotations

import sys
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
