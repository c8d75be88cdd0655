"""At-least-once delivery on a real zenoh bus (loopback, random port, `--fast`): our
publisher dropping 5 % of its first puts, reordering them, or sending each twice gives
setpoints bit-identical to the lossless run; a resend with other content is rejected."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent.parent))

from bench.corpus import load_corpus

from delivery_harness import bus_config, deliver_then_run, rechunk, status
from lookahead.checker import LimitChecker
from lookahead.config import default_config
from lookahead.protocol import Segment
from service_harness import check_job, point_segments

#: the issue's kind of job: a tube winding, cut into 20-point segments (113 of them)
PATH = "w-issue-tube1450-R100-a45-sine-2mm"
CHUNK = 20


def _arrays(batches):
    return [np.vstack([getattr(b, name) for b in batches]) for name in ("pos", "vel", "acc")]


@pytest.mark.parametrize("method", ["lp", pytest.param("heuristic", marks=pytest.mark.slow)])
def test_lossy_reordered_and_doubled_delivery_is_bit_identical(harness_factory, method):
    (corpus_path,) = load_corpus("fast", pattern=PATH)
    h = harness_factory(bus_config(corpus_path.config, method))
    base = rechunk(corpus_path.segments, "x", CHUNK)
    start, end = base[0].points[0], base[-1].points[-1]
    variants = {"lossless": {}, "drop5": {"drop_rate": 0.05, "seed": 7},
                "reorder": {"reorder": 16, "seed": 3}, "twice": {"duplicate": True}}
    runs = {}
    for name, options in variants.items():
        segs = rechunk(corpus_path.segments, f"job-{name}", CHUNK)
        batches, pub = deliver_then_run(h, segs, end, name, **options)
        runs[name] = (batches, pub.stats)
        check_job(batches, h.cfg, start, end)
    ref = _arrays(runs["lossless"][0])
    for name, (batches, _) in runs.items():
        got = _arrays(batches)
        assert all(a.shape == b.shape and np.array_equal(a, b) for a, b in
                   zip(got, ref, strict=True)), f"{name}: setpoints differ from lossless"
        checker = LimitChecker(h.cfg.machine.limits, h.cfg.machine.dt)
        checker.feed(got[0])
        assert checker.report().violations == 0
    # the variants did what they say, and the service asked for exactly what was dropped
    drop = runs["drop5"][1]
    assert drop["dropped"] >= 2 and drop["resent_missing"] + drop["resent_stalled"] >= \
        drop["dropped"]
    assert drop["missing_events"] >= 1
    assert runs["lossless"][1]["dropped"] == 0 and runs["lossless"][1]["missing_events"] == 0
    missing = h._events_of("missing", None)
    assert {e.job for e in missing} <= {"job-drop5", "job-reorder"}
    assert all(isinstance(e.extra["seq"], int) for e in missing)
    assert not h._events_of("fault", None)
    assert h.service.engine.fallbacks == 0 and h.service.engine.replan_failures == 0
    # nothing was rejected: duplicates and resends are ignored silently
    assert not [e for e in h._events_of("rejected", None) if e.job.startswith("job-")]


def test_a_resend_with_other_points_is_rejected_and_the_first_kept(harness_factory):
    h = harness_factory(bus_config(default_config()))
    t = np.linspace(0.0, 1.0, 300)
    pts = np.column_stack([400.0 * t, 360.0 * np.sin(2 * np.pi * t)])
    segs = point_segments("conflict", pts, [30] * 10)
    for seg in segs[:3]:
        h.send(seg)
    h.send(segs[6])  # waits for 3..5
    h.wait_event("missing", "conflict", count=1)
    changed = [Segment("conflict", s.seq, s.axes, "points", s.last, points=s.points + 7.0)
               for s in (segs[1], segs[6])]
    for seg in changed:  # one already taken in, one waiting
        h.send(seg)
    rejected = h.wait_event("rejected", "conflict", count=2)
    assert sorted(e.extra["seq"] for e in rejected) == [1, 6]
    assert all("different content" in e.extra["reason"] for e in rejected)
    for seg in segs[3:6] + segs[7:]:
        h.send(seg)
    pos, _, _ = check_job(h.wait_final("conflict"), h.cfg, pts[0], pts[-1])
    # the path went through the first version's points, not the changed ones
    for seg, other in zip((segs[1], segs[6]), changed, strict=True):
        mid = seg.points[len(seg.points) // 2]
        assert np.min(np.linalg.norm(pos - mid, axis=1)) < 0.5
        assert np.min(np.linalg.norm(pos - other.points[len(seg.points) // 2], axis=1)) > 3.0
    assert not h._events_of("fault", None)
    st = status(h)
    assert st.state == "idle" and st.receiving is None and st.accepting


def test_publish_cli_with_drop_rate_recovers(tmp_path):
    """`lookahead publish --drop-rate`: the demo of recovery, as processes on the bus."""
    import subprocess

    from test_clients_bus import bus_env, lookahead, stop, wait_alive

    env = bus_env("heuristic")
    service = lookahead(env, "serve", "--fast", "--log-level", "WARNING")
    try:
        wait_alive(env, "planner")
        pub = subprocess.run([sys.executable, "-m", "lookahead", "publish", "tube-1450",
                              "--job", "dropped", "--chunk", "40", "--drop-rate", "0.1",
                              "--seed", "4", "--timeout", "60"], env=env,
                             capture_output=True, text=True, timeout=90)
    finally:
        stop(service)
    assert pub.returncode == 0, pub.stderr
    assert "finished" in pub.stderr
    line = next(x for x in pub.stderr.splitlines() if "delivery:" in x)
    dropped = int(line.split("delivery: ")[1].split()[0])
    resent = int(line.split(", ")[-1].split()[0])
    assert dropped >= 1 and resent >= dropped, line
