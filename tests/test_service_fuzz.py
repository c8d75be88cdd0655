"""Hostile input on a real zenoh bus (loopback, random port, `--fast`): seeded random
segment payloads and command queries. The service stays up and answers the status, every
`rejected` carries a reason, every refused command says why, and a good job runs after."""

from __future__ import annotations

import sys
from pathlib import Path

import msgpack
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from delivery_harness import bus_config, status
from lookahead.config import default_config
from lookahead.protocol import COMMANDS, CommandReply, key
from service_harness import Harness, check_job, point_segments

N_SEGMENTS = 400
N_COMMANDS = 120
HUGE_SEGMENT = msgpack.packb({"v": 1, "job": "fz-huge", "seq": 0, "axes": ["X", "C"],
                              "kind": "points", "last": True,
                              "points": [[0.0, float(i)] for i in range(200_000)]})
BIG = (2**64 - 1, 2**63, -(2**63), 1e308, -1e308, 1e300, 2**53 + 1, 0, -1)


def _junk(rng: np.random.Generator):
    """A random value of a random type (maps, arrays, huge numbers, bytes, nil...)."""
    pick = int(rng.integers(0, 10))
    if pick == 0:
        return BIG[int(rng.integers(0, len(BIG)))]
    if pick == 1:
        return float(rng.normal() * 10.0 ** int(rng.integers(-300, 300)))
    if pick == 2:
        return "".join(chr(int(c)) for c in rng.integers(32, 0x2FFF, int(rng.integers(0, 80))))
    if pick == 3:
        return rng.bytes(int(rng.integers(0, 64)))
    if pick == 4:
        return None
    if pick == 5:
        return bool(rng.integers(0, 2))
    if pick == 6:
        return [float(x) for x in rng.normal(size=int(rng.integers(0, 5)))]
    if pick == 7:
        return {"a": 1, "b": [1, 2]}
    if pick == 8:
        return [[float(x) for x in row] for row in rng.normal(size=(3, 2))]
    return int(rng.integers(-10, 10))


def _segment(rng: np.random.Generator, i: int) -> bytes:
    """A segment payload broken in one or more random ways. Structurally valid ones never
    have seq 0 (they wait for a seq 0 that never comes, until the gap timeout), so that
    no hostile job moves the machine."""
    kind = i % 12
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 200)))
    if kind == 1:  # not a map
        return msgpack.packb(_junk(rng), use_bin_type=True)
    msg = {"v": 1, "job": f"fz{i % 7}", "seq": int(rng.integers(1, 50)), "axes": ["X", "C"],
           "kind": "points", "last": bool(rng.integers(0, 2)),
           "points": rng.normal(size=(int(rng.integers(1, 6)), 2)).tolist()}
    if kind == 2:  # the seq extremes (never 0, see above)
        msg["seq"] = BIG[int(rng.integers(0, len(BIG)))] or 2**64 - 1
    elif kind == 3:  # 200k points (a few: each costs the service ~0.1 s to read)
        if i % 48 != 3:
            return rng.bytes(int(rng.integers(0, 20)))
        return HUGE_SEGMENT
    elif kind == 4:  # non-positive weights
        msg.update(kind="nurbs", degree=2, ctrl=[[0, 0], [1, 1], [2, 0]],
                   knots=[0, 0, 0, 1, 1, 1], weights=[1.0, float(-rng.random()), 0.0], seq=0)
    elif kind == 5:  # huge coordinates
        msg["points"] = [[0.0, 0.0], [float(BIG[int(rng.integers(3, 6))]), 1.0]]
        msg["seq"] = 0
    elif kind == 6:  # random fields replaced by junk
        for name in rng.choice(sorted(msg), size=int(rng.integers(1, 4)), replace=False):
            msg[str(name)] = _junk(rng)
        if msg.get("seq") == 0:
            msg["seq"] = 1
    elif kind == 7:  # unknown keys and a missing one
        msg[str(rng.integers(0, 1e6))] = _junk(rng)
        del msg[["v", "job", "seq", "axes", "kind", "last"][int(rng.integers(0, 6))]]
    elif kind == 8:  # bad b-splines
        msg.update(kind="bspline", degree=int(rng.integers(-2, 9)),
                   ctrl=rng.normal(size=(int(rng.integers(1, 5)), 2)).tolist(),
                   knots=sorted(rng.normal(size=int(rng.integers(0, 10))).tolist()), seq=0)
    elif kind == 9:  # a conflicting resend of a seq (valid, never starts: seq >= 1)
        msg["seq"] = 1
        msg["job"] = "fz-conflict"
    elif kind == 10:  # non-string keys, nesting
        return msgpack.packb({1: 2, "v": {"v": [msg]}}, use_bin_type=True)
    else:  # truncated payload
        raw = msgpack.packb(msg, use_bin_type=True)
        return raw[: int(rng.integers(1, len(raw)))]
    return msgpack.packb(msg, use_bin_type=True)


def _command(h: Harness, rng: np.random.Generator, i: int) -> CommandReply | None:
    verbs = [*COMMANDS, "launch", "", "hold/now", "ÿ" * 40, "override"]
    verb = verbs[int(rng.integers(0, len(verbs)))] or "x"
    if i % 3 == 0:
        payload = rng.bytes(int(rng.integers(0, 40)))
    elif i % 3 == 1:
        payload = msgpack.packb(_junk(rng), use_bin_type=True)
    else:
        payload = msgpack.packb({"value": _junk(rng)}, use_bin_type=True)
    replies = list(h.client.get(key(h.ns, "cmd", verb), payload=payload, timeout=10.0))
    if not replies:  # a verb with a "/" is another key: nobody answers it
        assert "/" in verb
        return None
    return CommandReply.decode(replies[0].ok.payload.to_bytes())


@pytest.fixture
def harness():
    # a short gap timeout: the hostile jobs that wait for a seq 0 end soon
    h = Harness(bus_config(default_config(), "heuristic", gap_timeout_s=1.0), fast=True)
    yield h
    h.close()


def test_hostile_segments_and_commands_leave_the_service_serving(harness):
    h = harness
    rng = np.random.default_rng(2026)
    for i in range(N_SEGMENTS):
        h.send(_segment(rng, i))
        if i % 50 == 0:
            assert status(h).state in ("idle", "fault")  # alive and answering
    refused = 0
    for i in range(N_COMMANDS):
        reply = _command(h, rng, i)
        if reply is not None and not reply.ok:
            assert reply.error and isinstance(reply.error, str)
            refused += 1
    assert refused > N_COMMANDS // 2
    assert h.thread.is_alive()
    # every hostile job ends (gap timeout), then the service is idle and nothing moved
    h.wait_for(lambda: not h.service.engine.busy, timeout=30, what="the hostile jobs ending")
    assert not h.batches
    rejected = h._events_of("rejected", None)
    assert len(rejected) >= N_SEGMENTS // 2
    assert all(isinstance(e.extra.get("reason"), str) and e.extra["reason"] for e in rejected)
    assert not [e for e in rejected if e.extra["reason"].startswith("internal")]
    reasons = " | ".join(e.extra["reason"] for e in rejected)
    for expected in ("payload:", "rows exceeds the cap", "weights[", "beyond", "seq:"):
        assert expected in reasons, expected
    assert all(isinstance(e.extra["seq"], int) for e in h._events_of("missing", None))
    # a good job runs afterwards, exactly as on a fresh service
    assert h.command("reset").ok and h.command("override", 1.0).ok
    t = np.linspace(0.0, 1.0, 200)
    pts = np.column_stack([300.0 * t, 180.0 * np.sin(2 * np.pi * t)])
    for seg in point_segments("good", pts, [40] * 5):
        h.send(seg)
    check_job(h.wait_final("good"), h.cfg, pts[0], pts[-1])
    assert not h._events_of("rejected", "good") and not h._events_of("fault", "good")
    st = status(h)
    assert st.state == "idle" and st.accepting and st.buffered_points == 0
