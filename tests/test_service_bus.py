"""The planner service on a real zenoh bus (loopback, random ports), `--fast` mode."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import msgpack
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from lookahead.geometry.winding import preset_points
from lookahead.protocol import Status
from service_harness import (
    Harness,
    check_job,
    point_segments,
    random_sizes,
    service_config,
)


@pytest.fixture
def harness_factory():
    made: list[Harness] = []

    def make(method: str = "heuristic", fast: bool = True, **service) -> Harness:
        h = Harness(service_config(method, **service), fast=fast)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()


def _stream(h: Harness, job: str, points: np.ndarray, seed: int) -> None:
    for seg in point_segments(job, points, random_sizes(np.random.default_rng(seed),
                                                        len(points))):
        h.send(seg)


@pytest.mark.parametrize(("preset", "method"), [
    ("tube-1450", "heuristic"),
    ("tube-1450", "lp"),  # the LP in the service, in every CI run
    pytest.param("tube-9570", "heuristic", marks=pytest.mark.slow),
    pytest.param("tube-9570", "lp", marks=pytest.mark.slow),
])
def test_preset_streamed_in_random_chunks(harness_factory, preset, method):
    h = harness_factory(method)
    _, pts, _ = preset_points(preset)
    _stream(h, "job-a", pts, seed=len(pts))
    batches = h.wait_final("job-a", timeout=600)
    pos, _, _ = check_job(batches, h.cfg, pts[0], pts[-1])
    finished = h.wait_event("job_finished", "job-a")[0]
    assert finished.extra["duration_s"] == pytest.approx((len(pos) - 1) * h.cfg.machine.dt)
    assert not h._events_of("rejected", None) and not h._events_of("fault", None)
    # the samples pass through the programmed points (the path interpolates them)
    mid = pts[len(pts) // 2]
    assert np.min(np.linalg.norm(pos - mid, axis=1)) < 1.0


def test_hold_resume_then_abort_keep_limits(harness_factory):
    h = harness_factory()
    _, pts, _ = preset_points("tube-1450")
    _stream(h, "job-h", pts, seed=1)
    h.wait_for(lambda: sum(b.n for b in h.batches) > 1500, what="1500 samples")
    assert h.command("hold").ok
    def at_rest() -> bool:
        st = Status.decode(h.status_bytes())
        return st.state == "holding" and st.horizon_s == 0.0

    h.wait_for(at_rest, what="holding at rest")
    # the status answer and the setpoints travel separately: the rest batch may land later
    h.wait_for(lambda: np.all(np.abs(h.batches[-1].vel[-1]) <= 1e-9), timeout=5.0,
               what="the held batch at rest")
    n_held = sum(b.n for b in h.job_batches("job-h"))
    assert h.command("resume").ok
    h.wait_for(lambda: sum(b.n for b in h.batches) > n_held + 1000, what="motion again")
    assert h.command("abort").ok
    batches = h.wait_final("job-h")
    pos, _, _ = check_job(batches, h.cfg, pts[0], h.job_batches("job-h")[-1].pos[-1])
    assert h.wait_event("job_finished", "job-h")[0].extra.get("aborted") is True
    assert np.linalg.norm(pos[-1] - pts[-1]) > 1.0  # stopped short of the end
    assert not h.command("resume").ok  # nothing to resume any more


def test_override_half_and_back_keeps_limits(harness_factory):
    h = harness_factory()
    _, pts, _ = preset_points("tube-1450")
    _stream(h, "job-o", pts, seed=2)
    h.wait_for(lambda: sum(b.n for b in h.batches) > 1200, what="1200 samples")
    assert h.command("override", 0.5).ok
    h.wait_for(lambda: sum(b.n for b in h.batches) > 5000, what="5000 samples")
    assert h.command("override", 1.0).ok
    batches = h.wait_final("job-o", timeout=60)
    _, vel, _ = check_job(batches, h.cfg, pts[0], pts[-1])
    vmax = np.asarray(h.cfg.machine.vmax)
    # before the change an axis runs faster than half its limit; well after it, none does
    assert np.any(np.abs(vel[:1200]) > 0.6 * vmax)
    assert np.all(np.abs(vel[3500:4500]) <= 0.5 * vmax * (1 + 1e-9))
    assert np.any(np.abs(vel[-3000:]) > 0.6 * vmax)  # and back to full speed
    assert not h.command("override", 2.0).ok  # out of range


def test_publisher_stops_half_way_then_finishes(harness_factory):
    h = harness_factory()
    _, pts, _ = preset_points("tube-1450")
    segs = point_segments("job-s", pts, random_sizes(np.random.default_rng(3), len(pts)))
    half = len(segs) // 2
    for seg in segs[:half]:
        h.send(seg)
    starved = h.wait_event("starved", "job-s", timeout=30)[0]

    def through_starved() -> bool:  # events and setpoints are separate topics: no order
        # (called under h.lock, so h.batches directly)
        return any(b.job == "job-s" and b.k0 + b.n - 1 >= starved.k for b in h.batches)

    h.wait_for(through_starved, what="the setpoints up to the starved event")
    batches = h.job_batches("job-s")
    sent_end = segs[half - 1].points[-1]
    np.testing.assert_allclose(batches[-1].pos[-1], sent_end, atol=1e-6)
    np.testing.assert_allclose(batches[-1].vel[-1], 0.0, atol=1e-9)
    assert starved.k == batches[-1].k0 + batches[-1].n - 1
    assert Status.decode(h.status_bytes()).state == "starved"
    for seg in segs[half:]:
        h.send(seg)
    check_job(h.wait_final("job-s"), h.cfg, pts[0], pts[-1])


def _malformed(rng: np.random.Generator, i: int) -> bytes:
    good = {"v": 1, "job": "bad", "seq": i, "axes": ["X", "C"], "kind": "points",
            "last": False, "points": [[0.0, 0.0], [1.0, 1.0]]}
    kind = i % 20
    msg = dict(good)
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 64)))
    if kind == 1:
        return msgpack.packb([1, 2, 3])
    if kind == 2:
        del msg[["v", "job", "seq", "axes", "kind", "last"][i % 6]]
    elif kind == 3:
        msg["v"] = 2
    elif kind == 4:
        msg["job"] = "no spaces allowed"
    elif kind == 5:
        msg["seq"] = -1
    elif kind == 6:
        msg["axes"] = ["X", "Y"]
    elif kind == 7:
        msg["kind"] = "arc"
    elif kind == 8:
        msg["points"] = [[0.0, math.nan]]
    elif kind == 9:
        msg["points"] = [[0.0, 1.0], [2.0]]
    elif kind == 10:
        msg["points"] = []
    elif kind == 11:
        msg["fit"] = "spline"  # not a fit (linear and smooth are, since the fits work)
    elif kind == 12:
        msg["feed"] = -5.0
    elif kind == 13:
        msg.update(kind="bspline", degree=3, ctrl=[[0, 0], [1, 1], [2, 0], [3, 1]],
                   knots=[0, 0, 0, 1, 1, 1])
    elif kind == 14:
        msg.update(kind="nurbs", degree=2, ctrl=[[0, 0], [1, 1], [2, 0]],
                   knots=[0, 0, 0, 1, 1, 1], weights=[1, -1, 1])
    elif kind == 15:
        msg.update(kind="bspline", degree=9, ctrl=[[0, 0], [1, 1]], knots=[0, 1])
    elif kind == 16:
        msg["last"] = "yes"
    elif kind == 17:
        msg["seq"] = 1.5
    elif kind == 18:
        msg["points"] = "1,2"
    else:
        return msgpack.packb({"v": 1}) + b"\xc1"
    return msgpack.packb(msg)


def test_malformed_messages_are_rejected_then_a_job_is_perfect(harness_factory):
    h = harness_factory()
    rng = np.random.default_rng(4)
    for i in range(1000):
        h.send(_malformed(rng, i))
    rejected = h.wait_event("rejected", count=1000, timeout=30)
    assert len(rejected) == 1000
    assert all(isinstance(e.extra.get("reason"), str) and e.extra["reason"] for e in rejected)
    # the reason names the field, e.g. "points[0][1]: must be finite"
    assert any(e.extra["reason"].startswith("points[0][1]") for e in rejected)
    assert any(e.extra["reason"].startswith("axes") for e in rejected)
    assert not h.batches
    _, pts, _ = preset_points("tube-1450")
    _stream(h, "good", pts, seed=5)
    check_job(h.wait_final("good"), h.cfg, pts[0], pts[-1])
    assert not h._events_of("fault", None)


def test_status_queryable_and_liveliness(harness_factory):
    h = harness_factory()
    status = Status.decode(h.status_bytes())
    assert status.state == "idle" and status.planner == "heuristic"
    replies = list(h.client.liveliness().get(f"{h.ns}/alive/planner", timeout=5.0))
    assert [str(r.ok.key_expr) for r in replies] == [f"{h.ns}/alive/planner"]
    reply = h.command("hold")
    assert not reply.ok and "no job" in reply.error


def test_curve_pieces_over_the_bus_stop_only_at_the_corner(harness_factory):
    from test_stream_jobs import CORNER, SMOOTH_JOIN, curve_job, path_speed

    h = harness_factory()
    for seg in curve_job("curves"):
        h.send(seg)
    pos, vel, _ = check_job(h.wait_final("curves"), h.cfg, [0.0, 0.0], [0.0, 0.0])
    speed = path_speed(vel, h.cfg)
    i = int(np.argmin(np.linalg.norm(pos - CORNER, axis=1)))
    # at rest within dt/2 of that sample (the bound of test_stream_jobs' engine test: a
    # plan through the corner in one piece rests there between two samples)
    jerk = float(np.linalg.norm(h.cfg.machine.limits.jmax * np.asarray(h.cfg.machine.path_scale)))
    assert np.linalg.norm(pos[i] - CORNER) < 1e-6
    assert speed[i] <= 0.5 * jerk * (h.cfg.machine.dt / 2) ** 2
    near_join = np.linalg.norm(pos - SMOOTH_JOIN, axis=1) < 1.0
    assert near_join.any() and np.min(speed[near_join]) > 1.0
    assert not h._events_of("rejected", None) and not h._events_of("fault", None)


def test_a_job_elsewhere_is_rejected_and_the_next_one_from_here_runs(harness_factory):
    h = harness_factory()
    line = np.array([[0.0, 0.0], [200.0, 100.0]])
    h.send(point_segments("one", line, [2])[0])
    end = check_job(h.wait_final("one"), h.cfg, line[0], line[-1])[0][-1]
    h.send(point_segments("two", line, [2])[0])  # starts at (0, 0): not where we are
    (rejected,) = h.wait_event("rejected", "two")
    assert rejected.extra["reason"].startswith("points[0]")
    # the status a client reads after the event already knows about it
    assert Status.decode(h.status_bytes()).state == "idle"
    back = np.vstack([end, [50.0, 0.0]])
    h.send(point_segments("three", back, [2])[0])
    check_job(h.wait_final("three"), h.cfg, end, back[-1])
    assert not h.job_batches("two")
