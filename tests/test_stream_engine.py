"""The deterministic engine without a bus: replay identity, assembly rules, faults."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.protocol import Command, Segment, SetpointBatch
from lookahead.stream.engine import Engine
from lookahead.stream.planners import make_planner
from lookahead_clients.replay import batch_inputs

AXES = ("X", "C")


def _points(n: int = 400) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    return np.column_stack([300.0 * np.sin(2 * np.pi * t), 720.0 * t])


def _segments(job: str, pts: np.ndarray, size: int) -> list[Segment]:
    chunks = [pts[i:i + size] for i in range(0, len(pts), size)]
    return [Segment(job, i, AXES, "points", i == len(chunks) - 1, points=c)
            for i, c in enumerate(chunks)]


def _run(engine: Engine, feed: dict[int, list[Segment]], limit: int = 100000):
    """Call next_batch until the job ends; before call i submit feed.get(i)."""
    out = []
    for i in range(limit):
        for seg in feed.get(i, []):
            engine.submit(seg)
        batch = engine.next_batch()
        if batch is not None:
            out.append(batch)
            if batch.final:
                return out
    raise AssertionError("the job did not finish")


def test_replay_from_applied_lists_is_bit_identical():
    cfg = default_config()
    segs = _segments("r", _points(), 37)
    first = _run(Engine(cfg, make_planner("heuristic")), {0: segs[:3], 40: segs[3:6],
                                                          90: segs[6:]})
    # replay: feed the segments named in each batch's `applied` before asking for it
    by_id = {(s.job, s.seq): s for s in segs}
    replay_engine = Engine(cfg, make_planner("heuristic"))
    again = []
    for rec in first:
        for ident in rec.applied:
            replay_engine.submit(by_id[ident])
        batch = None
        while batch is None:
            batch = replay_engine.next_batch()
        again.append(batch)
    assert len(again) == len(first)
    for a, b in zip(first, again, strict=True):
        assert (a.k0, a.n, a.final, a.applied) == (b.k0, b.n, b.final, b.applied)
        assert np.array_equal(a.pos, b.pos) and np.array_equal(a.acc, b.acc)
    assert check_positions(np.vstack([b.pos for b in first]), cfg.machine.limits,
                           cfg.machine.dt).ok


def test_replay_with_commands_is_bit_identical():
    """Hold, resume and overrides, taken in between segments, are listed in the batches'
    `commands` (with their place among the `applied` segments) and replay exactly."""
    cfg = default_config()
    segs = _segments("c", _points(), 37)
    live = Engine(cfg, make_planner("lp"))
    script = {30: [Command("override", 0.6)], 60: [Command("hold")],
              90: [Command("resume"), Command("override", 1.2)], 120: [Command("reset")]}
    feed = {0: segs[:3], 60: segs[3:6], 120: segs[6:]}
    first = []
    for i in range(100000):
        for seg in feed.get(i, [])[:1]:
            live.submit(seg)
        for cmd in script.get(i, []):
            live.command(cmd)
        for seg in feed.get(i, [])[1:]:
            live.submit(seg)
        batch = live.next_batch()
        if batch is not None:
            first.append(SetpointBatch.decode(batch.encode()))  # through the wire format
            if batch.final:
                break
    listed = [c for b in first for c in b.commands]
    assert [(v, x) for v, x, _ in listed] == [(c.verb, c.value) for i in sorted(script)
                                              for c in script[i]]
    # some command sits between two segments of its batch: the interleaving is exercised
    assert any(0 < c[2] < len(b.applied) for b in first for c in b.commands)
    by_id = {(s.job, s.seq): s for s in segs}
    replay_engine = Engine(cfg, make_planner("lp"))
    for rec in first:
        for item in batch_inputs(rec):
            if isinstance(item, Command):
                replay_engine.command(item)
            else:
                replay_engine.submit(by_id[item])
        batch = None
        while batch is None:
            batch = replay_engine.next_batch()
        assert (batch.k0, batch.n, batch.final) == (rec.k0, rec.n, rec.final)
        assert np.array_equal(batch.pos, rec.pos) and np.array_equal(batch.acc, rec.acc)
    pos = np.vstack([b.pos for b in first])
    assert check_positions(pos, cfg.machine.limits, cfg.machine.dt).ok


def test_duplicates_wrong_axes_and_late_segments_are_rejected():
    cfg = default_config()
    eng = Engine(cfg, make_planner("heuristic"))
    segs = _segments("d", _points(), 100)
    eng.submit(segs[0])
    assert eng.submit(segs[0]) == []  # the same again (at-least-once delivery): ignored
    changed = Segment("d", 0, AXES, "points", False, points=segs[0].points + 1.0)
    events = eng.submit(changed)  # the same seq with other points: rejected, first kept
    assert [e.type for e in events] == ["rejected"]
    assert "different content" in events[0].extra["reason"]
    bad_axes = Segment("d", 1, ("X", "Y"), "points", False, points=np.ones((2, 2)))
    assert eng.submit(bad_axes)[0].extra["reason"].startswith("axes")
    for seg in reversed(segs[1:]):  # out of order: they wait, then go in order
        assert eng.submit(seg) == []
    batches = _run(eng, {})
    assert np.allclose(batches[-1].pos[-1], _points()[-1])
    late = eng.submit(segs[1])
    assert late[0].type == "rejected" and "finished" in late[0].extra["reason"]


def test_gap_timeout_ends_the_job_at_what_it_has_then_the_next_job_runs():
    cfg = default_config()
    eng = Engine(cfg, make_planner("heuristic"))
    segs = _segments("g", _points(), 100)
    eng.submit(segs[0], now_s=0.0)
    eng.submit(segs[1], now_s=0.0)
    eng.submit(segs[3], now_s=0.0)  # seq 2 never comes
    # the job starts after START_WAIT_S (too little geometry for the horizon), then moves
    out = [b for b in (eng.next_batch() for _ in range(90)) if b is not None]
    assert len(out) > 20 and np.linalg.norm(out[-1].vel[-1]) > 1.0  # gap not yet timed out
    assert eng.expire_gaps(1.0) == []
    events = eng.expire_gaps(cfg.service.gap_timeout_s + 1.0)
    assert [e.type for e in events] == ["rejected", "fault"]
    assert events[0].extra["seq"] == 2 and events[1].extra["reason"].startswith("seq")
    assert eng.status().state == "fault"  # while the job runs out
    out += _run(eng, {})
    pos = np.vstack([b.pos for b in out])
    # it came to rest at the end of the contiguous points it had, within the limits
    np.testing.assert_allclose(pos[-1], segs[1].points[-1], atol=1e-6)
    np.testing.assert_allclose(out[-1].vel[-1], 0.0, atol=1e-9)
    assert check_positions(pos, cfg.machine.limits, cfg.machine.dt).ok
    finished = [e for e in eng.drain_events() if e.type == "job_finished"]
    assert finished[-1].extra.get("aborted") is True
    late = eng.submit(segs[2])
    assert late[0].type == "rejected" and "finished" in late[0].extra["reason"]
    status = eng.status()
    assert status.state == "idle" and status.error.startswith("seq")
    # not latched: a job that starts where the machine is runs without a reset
    nxt = _segments("next", np.vstack([pos[-1], pos[-1] + [50.0, 90.0]]), 10)
    eng.submit(nxt[0])
    batches = _run(eng, {})
    assert batches[0].job == "next" and batches[-1].final
    assert eng.status().error is None


def test_gap_in_a_queued_job_drops_only_that_job():
    cfg = default_config()
    eng = Engine(cfg, make_planner("heuristic"))
    pts = _points()
    for seg in _segments("a", pts, 100):
        eng.submit(seg, now_s=0.0)
    eng.submit(Segment("q", 1, AXES, "points", True, points=pts[::-1][:5]), now_s=0.0)
    first = eng.next_batch()
    events = eng.expire_gaps(cfg.service.gap_timeout_s + 1.0)
    assert [(e.type, e.job) for e in events] == [("rejected", "q"), ("fault", "q"),
                                                 ("job_finished", "q")]
    batches = [first, *_run(eng, {})]
    assert {b.job for b in batches} == {"a"} and batches[-1].final
    np.testing.assert_allclose(batches[-1].pos[-1], pts[-1], atol=1e-6)


def test_curve_pieces_must_join():
    cfg = default_config()
    eng = Engine(cfg, make_planner("heuristic"))
    knots = [0, 0, 0, 0, 1, 1, 1, 1]
    a = Segment("c", 0, AXES, "bspline", False, degree=3, knots=np.array(knots, float),
                ctrl=np.array([[0, 0], [10, 5], [20, 5], [30, 0]], float))
    gap = Segment("c", 1, AXES, "bspline", True, degree=3, knots=np.array(knots, float),
                  ctrl=np.array([[31, 0], [40, 5], [50, 5], [60, 0]], float))
    good = Segment("c", 1, AXES, "bspline", True, degree=3, knots=np.array(knots, float),
                   ctrl=np.array([[30, 0], [40, -5], [50, -5], [60, 0]], float))
    assert eng.submit(a) == []
    rejected = eng.submit(gap)
    assert rejected[0].type == "rejected" and rejected[0].extra["reason"].startswith("ctrl")
    assert eng.submit(good) == []  # the corrected piece takes the same seq
    batches = _run(eng, {})
    pos = np.vstack([b.pos for b in batches])
    assert check_positions(pos, cfg.machine.limits, cfg.machine.dt).ok
    np.testing.assert_allclose(pos[-1], [60.0, 0.0], atol=1e-9)


@pytest.mark.parametrize("verb", ["hold", "abort"])
def test_stop_commands_stop_short_within_limits(verb):
    cfg = default_config()
    eng = Engine(cfg, make_planner("heuristic"))
    for seg in _segments("h", _points(), 400):
        eng.submit(seg)
    out = [eng.next_batch() for _ in range(40)]
    assert eng.command(Command(verb)).ok
    while True:
        batch = eng.next_batch()
        if batch is None or batch.final:
            out.append(batch) if batch is not None else None
            break
        out.append(batch)
    pos = np.vstack([b.pos for b in out])
    vel = np.vstack([b.vel for b in out])
    assert check_positions(pos, cfg.machine.limits, cfg.machine.dt).ok
    np.testing.assert_allclose(vel[-1], 0.0, atol=1e-9)
    assert np.linalg.norm(pos[-1] - _points()[-1]) > 10.0
    assert eng.status().state == ("holding" if verb == "hold" else "idle")
