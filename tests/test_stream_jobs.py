"""Engine jobs end to end (no bus): B-spline / NURBS pieces, per-segment feed caps, and the
rule that a job starts where the machine is. Limits are judged by the checker only."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.protocol import Command, Segment
from lookahead.stream.engine import Engine
from lookahead.stream.planners import make_planner

AXES = ("X", "C")
CUBIC = np.array([0, 0, 0, 0, 1, 1, 1, 1], dtype=float)
SMOOTH_JOIN = np.array([30.0, 0.0])  # pieces 0 -> 1: same tangent direction
CORNER = np.array([60.0, 0.0])  # pieces 1 -> 2: tangent (10, 5) then (0, 20)
END = np.array([0.0, 0.0])


def curve_job(job: str, feed: float | None = None) -> list[Segment]:
    """Four pieces in (X mm, C deg): bspline, bspline, nurbs, bspline (a closed loop)."""
    def piece(seq: int, ctrl, kind: str = "bspline", weights=None) -> Segment:
        return Segment(job, seq, AXES, kind, seq == 3, degree=3, knots=CUBIC,
                       ctrl=np.array(ctrl, dtype=float), weights=weights, feed=feed)

    return [piece(0, [[0, 0], [10, 5], [20, 5], [30, 0]]),
            piece(1, [[30, 0], [40, -5], [50, -5], [60, 0]]),
            piece(2, [[60, 0], [60, 20], [50, 40], [40, 40]], "nurbs",
                  np.array([1.0, 0.7, 1.3, 1.0])),
            piece(3, [[40, 40], [20, 40], [0, 20], [0, 0]])]


def run_job(engine: Engine, segments: list[Segment], limit: int = 100000):
    """Submit everything, then take batches until the final one; (batches, pos, vel)."""
    for seg in segments:
        engine.submit(seg)
    out = []
    for _ in range(limit):
        batch = engine.next_batch()
        if batch is not None:
            out.append(batch)
            if batch.final:
                break
    assert out and out[-1].final, "the job did not finish"
    return out, np.vstack([b.pos for b in out]), np.vstack([b.vel for b in out])


def path_speed(vel: np.ndarray, cfg) -> np.ndarray:
    return np.linalg.norm(vel * np.asarray(cfg.machine.path_scale), axis=1)


@pytest.mark.parametrize("method", ["heuristic", "lp"])
def test_curve_pieces_stop_at_a_corner_and_flow_through_a_smooth_junction(method):
    cfg = default_config()
    eng = Engine(cfg, make_planner(method))
    _, pos, vel = run_job(eng, curve_job("curves"))
    report = check_positions(pos, cfg.machine.limits, cfg.machine.dt)
    assert report.ok, report.first
    np.testing.assert_allclose(pos[0], [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(pos[-1], END, atol=1e-6)
    np.testing.assert_allclose(vel[[0, -1]], 0.0, atol=1e-9)
    speed = path_speed(vel, cfg)
    # the machine is exactly at the corner at some sample, and at rest there
    at_corner = np.linalg.norm(pos - CORNER, axis=1)
    i = int(np.argmin(at_corner))
    # the rest instant lies within dt/2 of that sample: v <= J (dt/2)^2 / 2 there, J the
    # largest path jerk the axis limits allow
    jerk = float(np.linalg.norm(cfg.machine.limits.jmax * np.asarray(cfg.machine.path_scale)))
    assert at_corner[i] < 1e-6 and speed[i] <= 0.5 * jerk * (cfg.machine.dt / 2) ** 2
    assert speed[i - 50] > 1.0 and speed[i + 50] > 1.0  # not a long crawl around it
    # through the smooth junction it keeps moving: no sample near it is at rest
    near_join = np.linalg.norm(pos - SMOOTH_JOIN, axis=1) < 1.0
    assert near_join.any() and np.min(speed[near_join]) > 1.0
    assert eng.status().state == "idle"


def test_feed_capped_middle_segments_stay_under_their_feed():
    cfg = default_config()
    t = np.linspace(0.0, 1.0, 600)
    pts = np.column_stack([600.0 * t, 360.0 * t])  # a straight line: s is the scaled chord
    feed = 60.0
    capped = (2, 3)
    segs = [Segment("f", i, AXES, "points", i == 5, points=pts[i * 100:(i + 1) * 100],
                    feed=feed if i in capped else None) for i in range(6)]
    _, pos, vel = run_job(Engine(cfg, make_planner("heuristic")), segs)
    report = check_positions(pos, cfg.machine.limits, cfg.machine.dt)
    assert report.ok, report.first
    scale = np.asarray(cfg.machine.path_scale)
    s = np.linalg.norm((pos - pts[0]) * scale, axis=1)
    # segment i covers the path from segment i-1's last point to its own last point
    s_lo = np.linalg.norm((pts[capped[0] * 100 - 1] - pts[0]) * scale)
    s_hi = np.linalg.norm((pts[capped[-1] * 100 + 99] - pts[0]) * scale)
    speed = path_speed(vel, cfg)
    inside = (s >= s_lo) & (s <= s_hi)
    assert inside.sum() > 1000  # the capped stretch takes time at <= 60 mm/s
    assert np.max(speed[inside]) <= feed * (1 + 1e-6)
    assert np.max(speed[inside]) > 0.9 * feed  # the cap, not something else, binds
    assert np.max(speed[~inside]) > 3 * feed  # and it binds only there
    np.testing.assert_allclose(pos[-1], pts[-1], atol=1e-6)


def test_a_job_must_start_where_the_last_one_left_the_machine():
    cfg = default_config()
    eng = Engine(cfg, make_planner("heuristic"))
    # the first job after start-up: no known position, accepted wherever it starts
    line = np.array([[10.0, 5.0], [110.0, 95.0]])
    _, pos, _ = run_job(eng, [Segment("one", 0, AXES, "points", True, points=line)])
    here = pos[-1]
    assert np.abs(here - line[-1]).max() < 1e-9
    eng.drain_events()
    # a job that starts elsewhere is rejected and nothing moves
    away = Segment("two", 0, AXES, "points", False, points=line.copy())
    assert eng.submit(away) == []
    assert eng.next_batch() is None
    events = eng.drain_events()
    rejected = [e for e in events if e.type == "rejected"]
    assert [(e.job, e.extra["seq"]) for e in rejected] == [("two", 0)]
    assert rejected[0].extra["reason"].startswith("points[0]")
    assert "machine is at" in rejected[0].extra["reason"]
    assert [e.extra.get("aborted") for e in events if e.type == "job_finished"] == [True]
    later = eng.submit(Segment("two", 1, AXES, "points", True, points=line[::-1]))
    assert "rejected" in later[0].extra["reason"]
    # a job that starts where the machine is runs
    back = Segment("three", 0, AXES, "points", True, points=np.vstack([here, [0.0, 0.0]]))
    batches, pos, _ = run_job(eng, [back])
    assert batches[0].job == "three"
    np.testing.assert_allclose(pos[0], here, atol=0.0)


def test_after_an_abort_the_planned_next_job_is_rejected():
    cfg = default_config()
    eng = Engine(cfg, make_planner("heuristic"))
    line = np.array([[0.0, 0.0], [400.0, 300.0]])
    eng.submit(Segment("long", 0, AXES, "points", True, points=line))
    # queued behind it: a job planned from where "long" would have ended
    eng.submit(Segment("then", 0, AXES, "points", True,
                       points=np.vstack([line[-1], [0.0, 0.0]])))
    out = [eng.next_batch() for _ in range(30)]
    assert eng.command(Command("abort")).ok
    while not out[-1].final:
        out.append(eng.next_batch())
    stopped = out[-1].pos[-1]
    assert np.linalg.norm(stopped - line[-1]) > 10.0
    assert eng.next_batch() is None
    rejected = [e for e in eng.drain_events() if e.type == "rejected"]
    assert [e.job for e in rejected] == ["then"]
    assert not eng.busy
