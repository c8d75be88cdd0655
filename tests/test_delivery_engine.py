"""Delivery without a bus: the engine's gap announcements, duplicates, seq window, buffer
accounting (checked against tracemalloc) and the publisher's Outbox decisions."""

from __future__ import annotations

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from lookahead.config import default_config
from lookahead.protocol import Segment, Status
from lookahead.stream.assembler import MISSING_REPEAT_S
from lookahead.stream.engine import Engine
from lookahead.stream.planners import make_planner
from lookahead_clients.delivery import STALL_RESEND, Outbox
from lookahead_clients.job_source import make_segments

AXES = ("X", "C")


def _segments(job: str, n_points: int = 400, chunk: int = 40) -> list[Segment]:
    t = np.linspace(0.0, 1.0, n_points)
    pts = np.column_stack([300.0 * t, 200.0 * np.sin(2 * np.pi * t)])
    return make_segments(job, list(AXES), pts, chunk)


def _engine(**service) -> Engine:
    cfg = default_config()
    return Engine(replace(cfg, service=replace(cfg.service, **service)),
                  make_planner("heuristic"))


def _missing(events) -> list[int]:
    return [e.extra["seq"] for e in events if e.type == "missing"]


def test_missing_is_announced_at_once_and_repeated_until_the_resend():
    eng = _engine()
    segs = _segments("g")
    assert eng.submit(segs[0], 0.0) == []
    assert eng.announce_missing(0.0) == []  # nothing waits: no gap
    eng.submit(segs[2], 0.0)
    eng.submit(segs[5], 0.0)
    assert _missing(eng.announce_missing(0.01)) == [1, 3, 4]
    assert eng.announce_missing(0.02) == []
    t, repeats = 0.01, 0
    while t < 2.0:  # every seq is named again at least every 0.5 s
        t += 0.05
        got = _missing(eng.announce_missing(t))
        if got:
            assert got == [1, 3, 4]
            repeats += 1
    assert repeats >= int(2.0 / 0.5) and MISSING_REPEAT_S <= 0.5
    eng.submit(segs[1], 2.1)  # the resend: 1 and 2 go in, 3 and 4 are still missing
    assert _missing(eng.announce_missing(2.5)) == [3, 4]
    st = eng.status()
    assert (st.receiving, st.next_seq) == ("g", 3)


def test_a_gap_filled_just_before_the_timeout_does_not_end_the_job():
    eng = _engine()
    segs = _segments("t")
    timeout = eng.config.service.gap_timeout_s
    for seg in segs[:3] + segs[4:]:
        eng.submit(seg, 0.0)
    assert eng.expire_gaps(timeout - 0.01) == []
    assert eng.submit(segs[3], timeout - 0.01) == []
    assert eng.expire_gaps(10 * timeout) == []  # nothing waits any more
    batches = []
    while not batches or not batches[-1].final:
        batch = eng.next_batch()
        if batch is not None:
            batches.append(batch)
    np.testing.assert_allclose(batches[-1].pos[-1], segs[-1].points[-1], atol=1e-9)
    assert not [e for e in eng.drain_events() if e.type in ("fault", "rejected")]


def test_duplicates_are_ignored_and_conflicts_rejected_taken_in_or_waiting():
    eng = _engine()
    segs = _segments("d")
    eng.submit(segs[0])
    eng.submit(segs[3])  # waits
    as_ints = Segment("d", 0, AXES, "points", False, points=segs[0].points.copy())
    assert eng.submit(as_ints) == [] and eng.submit(segs[3]) == []
    assert eng.admission(segs[0]) == "duplicate" and eng.admission(segs[2]) == "gap"
    assert eng.admission(segs[5]) == "new"
    for seq in (0, 3):
        other = Segment("d", seq, AXES, "points", False, points=segs[seq].points * 2.0)
        (event,) = eng.submit(other)
        assert event.type == "rejected" and event.extra["seq"] == seq
        assert "different content" in event.extra["reason"]
    assert eng.status().queued == 2  # the first versions, and nothing else


@pytest.mark.parametrize("seq", [2**64 - 1, 65_536])
def test_a_seq_far_beyond_the_window_is_rejected(seq):
    eng = _engine()
    far = Segment("w", seq, AXES, "points", True, points=np.ones((2, 2)))
    (event,) = eng.submit(far)
    assert event.type == "rejected" and "beyond the next expected seq 0" in \
        event.extra["reason"]
    assert not eng.busy


def test_the_buffer_count_and_accepting_follow_the_caps():
    eng = _engine(max_buffered_points=100)
    segs = _segments("b", 400, 40)
    eng.submit(segs[0])
    eng.submit(segs[1])
    st = eng.status()
    assert st.buffered_points == 80 and st.accepting
    eng.submit(segs[3])  # waiting segments count too
    assert eng.status().buffered_points == 120 and not eng.status().accepting
    assert eng.full and eng.admission(segs[2]) == "gap" and eng.admission(segs[4]) == "new"
    decoded = Status.decode(eng.status().encode())
    assert (decoded.receiving, decoded.next_seq, decoded.accepting) == ("b", 2, False)


@pytest.mark.parametrize(("chunk", "n_points"), [(2, 600), (200, 6000)])
def test_the_byte_estimate_bounds_the_memory_taken(chunk, n_points):
    """tracemalloc: what the engine allocates for received segments stays below its own
    byte count (the count `max_buffered_bytes` is compared with)."""
    segs = _segments("m", n_points, chunk)
    eng = _engine()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for seg in segs:
            eng.submit(seg, 0.0)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    points, nbytes = eng.buffered
    assert points == n_points
    assert 0.05 * nbytes < grown < nbytes


def test_outbox_resends_what_is_missing_refused_or_stalled():
    payloads = [bytes([i]) for i in range(100)]
    box = Outbox("j", payloads, window=10, drop_rate=0.2, seed=1)
    first = box.due(0.0)
    assert box.blocked and box.stats.first_puts == 10  # the window
    assert len(first) == 10 - box.stats.dropped and box.stats.dropped > 0
    box.due(0.1)
    assert box.stats.first_puts == 10  # still blocked
    box.on_status("j", 5, True, 0.1)
    box.due(0.1)
    assert box.stats.first_puts == 15
    box.on_missing(3, 0.2)
    box.on_refused(12)
    box.on_status("j", 5, False, 0.2)  # full: only the missing one goes
    assert box.due(0.2) == [payloads[3]]
    box.on_status("other", 90, True, 0.3)  # another job's next_seq says nothing about ours
    assert box.next_seq == 5
    out = box.due(0.3)
    assert out[0] == payloads[12] and box.stats.resent_refused == 1
    # nothing progresses: after STALL_S the unconfirmed ones from next_seq go again
    assert box.due(0.5) == []
    stalled = box.due(1.4)
    assert stalled == payloads[5:5 + min(STALL_RESEND, 10)]
    assert box.due(2.0) == []  # the wait doubled
    box.on_status("j", 100, True, 2.1)  # everything is in: the rest goes, then nothing
    box.due(2.2)
    assert box.all_first_put and box.stats.first_puts == 100
    assert box.due(20.0) == []


def test_outbox_options_reorder_and_duplicate_only_change_first_puts():
    payloads = [bytes([i]) for i in range(40)]
    box = Outbox("j", payloads, window=100, reorder=8, seed=2, duplicate=True)
    out = box.due(0.0)
    assert len(out) == 80 and sorted(set(out)) == payloads and out != sorted(out)
    assert all(out[i] == out[i + 1] for i in range(0, 80, 2))
    assert all({p[0] // 8 for p in out[16 * b:16 * b + 16]} == {b} for b in range(5))
