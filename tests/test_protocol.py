"""Protocol: round trips of every message type and one named error per malformed field."""

from __future__ import annotations

import contextlib
import math
from typing import Any

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lookahead.protocol import (
    MAX_PAYLOAD_BYTES,
    MAX_SEGMENT_POINTS,
    Command,
    CommandReply,
    Event,
    ProtocolError,
    Segment,
    SetpointBatch,
    Status,
)

AXES = ("X", "C")


def points_map(**changes: Any) -> dict[str, Any]:
    msg = {"v": 1, "job": "tube.1450_a-1", "seq": 0, "axes": list(AXES), "kind": "points",
           "last": False, "points": [[0.0, 0.0], [1.0, 2.5], [2, 5]], "fit": "pchip"}
    msg.update(changes)
    return {k: v for k, v in msg.items() if v is not DROP}


def nurbs_map(**changes: Any) -> dict[str, Any]:
    w = math.sqrt(0.5)
    msg = {"v": 1, "job": "j", "seq": 3, "axes": list(AXES), "kind": "nurbs", "last": True,
           "degree": 2, "knots": [0, 0, 0, 1, 1, 1], "ctrl": [[1, 0], [1, 1], [0, 1]],
           "weights": [1, w, 1], "feed": 120.0}
    msg.update(changes)
    return {k: v for k, v in msg.items() if v is not DROP}


DROP = object()


def decode(msg: dict[str, Any]) -> Segment:
    return Segment.decode(msgpack.packb(msg, use_bin_type=True), axes=AXES)


def test_points_segment_round_trip() -> None:
    seg = decode(points_map())
    assert seg.kind == "points" and seg.fit == "pchip" and seg.seq == 0 and not seg.last
    assert seg.points.shape == (3, 2) and seg.points.dtype == np.float64
    again = Segment.decode(seg.encode(), axes=AXES)
    assert np.array_equal(again.points, seg.points)
    assert (again.job, again.seq, again.axes, again.fit, again.last) == (
        seg.job, seg.seq, seg.axes, seg.fit, seg.last)


def test_nurbs_segment_round_trip() -> None:
    seg = decode(nurbs_map())
    again = Segment.decode(seg.encode(), axes=AXES)
    assert again.kind == "nurbs" and again.degree == 2 and again.feed == 120.0 and again.last
    assert np.array_equal(again.knots, seg.knots)
    assert np.array_equal(again.ctrl, seg.ctrl)
    assert np.array_equal(again.weights, seg.weights)


def test_bspline_needs_no_weights() -> None:
    seg = decode(nurbs_map(kind="bspline", weights=DROP))
    assert seg.weights is None


def test_unknown_fields_are_ignored() -> None:
    assert decode(points_map(colour="red")).kind == "points"


def test_fit_defaults_to_cubic() -> None:
    assert decode(points_map(fit=DROP)).fit == "cubic"


@pytest.mark.parametrize(
    ("msg", "field", "words"),
    [
        (points_map(v=2), "v", "unsupported protocol version"),
        (points_map(v="1"), "v", "expected an integer"),
        (points_map(v=DROP), "v", "missing"),
        (points_map(job=""), "job", "1..64"),
        (points_map(job="a" * 65), "job", "1..64"),
        (points_map(job="bad job!"), "job", "1..64"),
        (points_map(job=7), "job", "expected a string"),
        (points_map(seq=-1), "seq", ">= 0"),
        (points_map(seq=1.5), "seq", "expected an integer"),
        (points_map(seq=True), "seq", "expected an integer"),
        (points_map(seq=DROP), "seq", "missing"),
        (points_map(axes=["X"]), "axes", "machine's axes"),
        (points_map(axes=["C", "X"]), "axes", "machine's axes"),
        (points_map(axes=[]), "axes", "non-empty"),
        (points_map(axes=["X", "X"]), "axes", "distinct"),
        (points_map(axes="XC"), "axes", "non-empty array"),
        (points_map(kind="arc"), "kind", "points, bspline, nurbs"),
        (points_map(last="yes"), "last", "true or false"),
        (points_map(last=DROP), "last", "missing"),
        (points_map(points=[]), "points", "non-empty"),
        (points_map(points=DROP), "points", "missing"),
        (points_map(points=[[0.0, 0.0], [1.0]]), "points[1]", "expected 2 values"),
        (points_map(points=[[0.0, 0.0, 0.0]]), "points[0]", "expected 2 values"),
        (points_map(points=[[0.0, float("nan")]]), "points[0][1]", "finite"),
        (points_map(points=[[float("inf"), 0.0]]), "points[0][0]", "finite"),
        (points_map(points=[[0.0, "1"]]), "points[0][1]", "expected a number"),
        (points_map(points=[3.0]), "points[0]", "row of numbers"),
        (points_map(fit="quintic"), "fit", "cubic, pchip, linear, smooth"),
        (points_map(tolerance=-0.1), "tolerance", ">= 0"),
        (points_map(tolerance=float("nan")), "tolerance", "finite"),
        (points_map(tolerance="0.1"), "tolerance", "expected a number"),
        (points_map(feed=0.0), "feed", "> 0"),
        (points_map(feed=-3), "feed", "> 0"),
        (points_map(feed=float("inf")), "feed", "finite"),
        (points_map(points=[[0.0, 0.0]] * (MAX_SEGMENT_POINTS + 1)), "points", "cap"),
        (nurbs_map(degree=0), "degree", ">= 1"),
        (nurbs_map(degree=6), "degree", "<= 5"),
        (nurbs_map(degree=DROP), "degree", "missing"),
        (nurbs_map(knots=[0, 0, 0, 1, 1]), "knots", "expected len(ctrl) + degree + 1 = 6"),
        (nurbs_map(knots=[0, 0, 0, 1, 1, 1, 1]), "knots", "= 6"),
        (nurbs_map(knots=[0, 0, 0.5, 1, 1, 1]), "knots", "clamped"),
        (nurbs_map(knots=[0, 0, 0, 2, 1, 1]), "knots[4]", "non-decreasing"),
        (nurbs_map(knots=[1, 1, 1, 1, 1, 1]), "knots", "positive length"),
        (nurbs_map(knots=[0, 0, 0, float("nan"), 1, 1]), "knots[3]", "finite"),
        (nurbs_map(weights=[1, 0, 1]), "weights[1]", "> 0"),
        (nurbs_map(weights=[1, -2, 1]), "weights[1]", "> 0"),
        (nurbs_map(weights=[1, 1]), "weights", "expected 3 entries"),
        (nurbs_map(weights=DROP), "weights", "missing"),
        (nurbs_map(ctrl=[[0, 0], [1, 1]]), "ctrl", "at least 3 control points"),
        (nurbs_map(ctrl=[[0, 0], [1, 1], [2, float("-inf")]]), "ctrl[2][1]", "finite"),
    ],
)
def test_malformed_segment_field_is_named(msg: dict[str, Any], field: str, words: str) -> None:
    with pytest.raises(ProtocolError) as info:
        decode(msg)
    assert info.value.field == field
    assert words in info.value.reason
    assert str(info.value).startswith(f"{field}: ")


@pytest.mark.parametrize(
    ("payload", "words"),
    [
        (b"\xc1", "not valid MessagePack"),
        (msgpack.packb([1, 2]), "expected a map"),
        (msgpack.packb({1: 2}), "keys must be strings"),
        (b"\x00" * (MAX_PAYLOAD_BYTES + 1), "exceeds the cap"),
    ],
)
def test_malformed_payload(payload: bytes, words: str) -> None:
    with pytest.raises(ProtocolError) as info:
        Segment.decode(payload, axes=AXES)
    assert info.value.field == "payload" and words in info.value.reason


def test_setpoint_batch_round_trip_is_bit_exact() -> None:
    rng = np.random.default_rng(1)
    pos, vel, acc = (rng.normal(size=(10, 2)) for _ in range(3))
    batch = SetpointBatch("job1", 4, 40, 0.001, AXES, pos, vel, acc, final=True,
                          applied=(("job1", 3), ("job2", 0)),
                          commands=(("hold", None, 0), ("override", 0.5, 2)))
    raw = batch.encode()
    assert isinstance(msgpack.unpackb(raw)["pos"], bytes)  # bin, not an array
    again = SetpointBatch.decode(raw)
    assert again.n == 10 and again.k0 == 40 and again.final and again.axes == AXES
    assert again.applied == (("job1", 3), ("job2", 0))
    assert again.commands == (("hold", None, 0), ("override", 0.5, 2))
    for a, b in ((again.pos, pos), (again.vel, vel), (again.acc, acc)):
        assert a.tobytes() == b.tobytes()


def test_setpoint_batch_checks_blob_sizes() -> None:
    z = np.zeros((2, 2))
    raw = msgpack.unpackb(SetpointBatch("j", 0, 0, 0.001, AXES, z, z, z, False).encode())
    raw["n"] = 3
    with pytest.raises(ProtocolError, match="pos: expected 48 bytes"):
        SetpointBatch.decode(msgpack.packb(raw, use_bin_type=True))


@pytest.mark.parametrize(("commands", "field"), [
    ([["jump", None, 0]], "commands[0][0]"),  # not a verb
    ([["override", "fast", 0]], "commands[0][1]"),
    ([["hold", None, 1]], "commands[0][2]"),  # after more segments than the batch applied
    ([["hold", None]], "commands[0]"),
    ({"hold": 1}, "commands"),
])
def test_setpoint_batch_rejects_bad_commands(commands, field) -> None:
    z = np.zeros((1, 2))
    raw = msgpack.unpackb(SetpointBatch("j", 0, 0, 0.001, AXES, z, z, z, False).encode())
    raw["commands"] = commands
    with pytest.raises(ProtocolError) as info:
        SetpointBatch.decode(msgpack.packb(raw, use_bin_type=True))
    assert info.value.field == field


def test_status_event_reply_command_round_trip() -> None:
    st_ = Status("running", "job1", 1234, 3, 1.5, 0.5, "lp", 2.25, None)
    assert Status.decode(st_.encode()) == st_
    ev = Event("rejected", "job1", 17, {"seq": 4, "reason": "points[2][0]: must be finite"})
    assert Event.decode(ev.encode()) == ev
    done = Event("job_finished", "job1", 9000, {"duration_s": 9.0, "aborted": True})
    assert Event.decode(done.encode()) == done
    for reply in (CommandReply(True), CommandReply(False, "no job")):
        assert CommandReply.decode(reply.encode()) == reply
    cmd = Command("override", 0.5)
    assert Command.decode("override", cmd.encode()) == cmd
    assert Command.decode("hold", b"") == Command("hold")


def test_status_time_left_round_trips_and_older_statuses_decode() -> None:
    done = Status("running", "job1", 1234, 0, 0.75, 1.0, "lp", 2.0, None,
                  plan_complete=True, remaining_s=0.75)
    assert Status.decode(done.encode()) == done
    # a status from before the fields existed: the end is not known to be planned
    old = msgpack.unpackb(done.encode())
    del old["plan_complete"], old["remaining_s"]
    decoded = Status.decode(msgpack.packb(old))
    assert decoded.plan_complete is False and decoded.remaining_s is None
    assert decoded.horizon_s == 0.75 and decoded.k == 1234
    for name, value in (("remaining_s", -1.0), ("remaining_s", "soon"),
                        ("plan_complete", 1)):
        with pytest.raises(ProtocolError) as info:
            Status.decode(msgpack.packb({**old, name: value}))
        assert info.value.field == name


@pytest.mark.parametrize("value", [0.0, -1.0, 1.51, float("nan")])
def test_override_out_of_range(value: float) -> None:
    with pytest.raises(ProtocolError) as info:
        Command.decode("override", Command("override", value).encode())
    assert info.value.field == "value"


def test_unknown_command_and_event() -> None:
    with pytest.raises(ProtocolError, match="verb"):
        Command.decode("explode", b"")
    with pytest.raises(ProtocolError, match="type"):
        Event.decode(msgpack.packb({"type": "boom", "job": None, "k": 0}))


_scalars = st.one_of(st.none(), st.booleans(), st.integers(-2**63, 2**64 - 1), st.floats(),
                     st.text(max_size=8), st.binary(max_size=8))
_values = st.recursive(_scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=20)
_keys = st.sampled_from(["v", "job", "seq", "axes", "kind", "last", "points", "fit", "degree",
                         "knots", "ctrl", "weights", "feed", "x"])


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(_keys, _values, max_size=12))
def test_random_maps_only_raise_protocol_error(msg: dict[str, Any]) -> None:
    with contextlib.suppress(ProtocolError):
        Segment.decode(msgpack.packb(msg, use_bin_type=True), axes=AXES)


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(_keys, _values, max_size=12), st.sampled_from(list(points_map().items())
                                                                      + list(nurbs_map().items())))
def test_near_valid_maps_only_raise_protocol_error(noise: dict[str, Any],
                                                   item: tuple[str, Any]) -> None:
    base = nurbs_map() if item[0] in ("degree", "knots", "ctrl", "weights") else points_map()
    base.update(noise)
    with contextlib.suppress(ProtocolError):
        Segment.decode(msgpack.packb(base, use_bin_type=True), axes=AXES)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_random_bytes_only_raise_protocol_error(raw: bytes) -> None:
    for decoder in (lambda b: Segment.decode(b, axes=AXES), SetpointBatch.decode,
                    Status.decode, Event.decode, CommandReply.decode):
        with contextlib.suppress(ProtocolError):
            decoder(raw)
