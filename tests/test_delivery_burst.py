"""Flow control on a real zenoh bus (loopback, random port, `--fast`): a burst of 10,000
small segments arrives complete with bounded memory, and a publisher that sends far more
than the caps hold is held back (refusals, resends) without losing a segment."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent.parent))

from bench.corpus import load_corpus

from delivery_harness import PublisherThread, bus_config, lead_in, rechunk, status
from lookahead.config import default_config
from lookahead.service import INCOMING_MAX, INCOMING_MAX_BYTES
from lookahead.stream.assembler import POINT_OVERHEAD_BYTES, SEGMENT_OVERHEAD_BYTES
from lookahead_clients.job_source import make_segments
from service_harness import check_job

N_BURST = 10_000


def test_burst_of_10000_segments_arrives_complete_with_bounded_memory(harness_factory):
    """The burst is queued behind a starved lead-in job, so that the service does nothing
    but take it in; then it starts and is aborted (planning 10,000 segments is not this
    test's business)."""
    h = harness_factory(bus_config(default_config(), "heuristic"))
    t = np.linspace(0.0, 1.0, N_BURST)
    pts = np.column_stack([200.0 * t, 90.0 * np.sin(2 * np.pi * t)])
    # a tolerance fit: the cheapest to take in per segment (the cubic fit checks excursions)
    segs = make_segments("burst", ["X", "C"], pts, chunk=1, fit="smooth")
    first, second = lead_in("lead", np.array([-50.0, 0.0]), pts[0], ("X", "C"))
    h.send(first)
    h.wait_event("starved", "lead", timeout=30)
    pub = PublisherThread(h.cfg, segs, timeout=120.0, window=N_BURST)  # no pacing at all
    deadline = time.monotonic() + 100.0
    while not (status(h).receiving == "burst" and status(h).next_seq == N_BURST):
        assert time.monotonic() < deadline and pub.thread.is_alive(), pub.messages
        time.sleep(0.1)
    st = status(h)
    stats = h.service.stats
    # nothing lost, nothing asked for again, nothing refused
    assert st.buffered_points == N_BURST  # (the lead-in is executed up to its end)
    assert not h._events_of("missing", "burst") and not h._events_of("rejected", "burst")
    # memory: the drain queue stayed within its caps, the engine holds the job's arrays
    # and a bounded overhead per segment
    assert stats.max_incoming <= INCOMING_MAX
    assert stats.max_incoming_bytes <= INCOMING_MAX_BYTES
    per_segment = 2 * 8 + SEGMENT_OVERHEAD_BYTES + POINT_OVERHEAD_BYTES
    assert stats.max_buffered_bytes <= (N_BURST + 4) * per_segment
    assert h.service._incoming.qsize() == 0
    h.send(second)
    h.wait_event("job_started", "burst", timeout=30)
    assert h.command("abort").ok
    (done,) = h.wait_event("job_finished", "burst", timeout=60)
    assert done.extra.get("aborted") is True
    assert pub.join(30) == 1 and any("aborted" in m for m in pub.messages)
    assert pub.stats["resent_missing"] == pub.stats["resent_refused"] == 0


def _bounds(cap_points: int, cap_bytes: int, window: int, seg_points: int, naxes: int
            ) -> tuple[int, int]:
    """What the service may hold at most: the caps, plus one segment taken in just below
    a cap, plus one segment per gap it fills while full (at most `window` gaps: the
    publisher keeps no more in flight)."""
    seg_bytes = seg_points * (naxes * 8 + POINT_OVERHEAD_BYTES) + SEGMENT_OVERHEAD_BYTES
    return cap_points + (window + 1) * seg_points, cap_bytes + (window + 1) * seg_bytes


def test_a_publisher_far_ahead_of_the_caps_is_held_back_and_loses_nothing(harness_factory):
    (corpus_path,) = load_corpus("fast", pattern="w-issue-tube1450-R100-a45-sine-2mm")
    cap_points, cap_bytes = 300, 20_000_000
    h = harness_factory(bus_config(corpus_path.config, "heuristic",
                                   max_buffered_points=cap_points,
                                   max_buffered_bytes=cap_bytes))
    segs = rechunk(corpus_path.segments, "ahead", 2)
    window = 600  # 1200 points in flight against a cap of 300
    # the timeout only guards against a hang (about 12 s alone; it took over 50 s beside a
    # CPU-heavy benchmark on the 2-core machine), so it is as generous as the other test's
    pub = PublisherThread(h.cfg, segs, timeout=120.0, window=window, drop_rate=0.02, seed=5)
    accepting_seen = set()
    while pub.thread.is_alive():
        accepting_seen.add(status(h).accepting)
        pub.thread.join(0.05)
    assert pub.join(1.0) == 0, pub.messages
    pts = np.vstack([s.points for s in segs])
    check_job(h.wait_final("ahead"), h.cfg, pts[0], pts[-1])
    stats = h.service.stats
    assert False in accepting_seen  # the status showed the buffer full
    assert stats.refused_full > 0 and pub.stats["refused"] > 0 and pub.stats["dropped"] > 0
    refusals = h._events_of("rejected", "ahead")
    assert refusals and all(e.extra.get("retry") and e.extra["reason"].startswith("buffer")
                            for e in refusals)
    assert not h._events_of("fault", None)
    assert h.service.engine.replan_failures == 0 and h.service.engine.fallbacks == 0
    max_points, max_bytes = _bounds(cap_points, cap_bytes, window, 2, 2)
    assert cap_points <= stats.max_buffered_points <= max_points
    assert stats.max_buffered_bytes <= max_bytes
    assert status(h).buffered_points == 0
