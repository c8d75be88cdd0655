"""Wire protocol version 1 (PROTOCOL.md): message types, MessagePack encoding, validation.

Every payload is one MessagePack map with string keys. `decode_*` functions turn bytes into
typed, validated messages or raise `ProtocolError` naming the field and what is wrong;
nothing else in the service sees raw bytes. Readers ignore keys they do not know.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np

VERSION = 1

#: Largest payload the service accepts on NS/segments, in bytes.
MAX_PAYLOAD_BYTES = 8 * 1024 * 1024
#: Largest number of points (kind = points) or control points (bspline/nurbs) in a segment.
MAX_SEGMENT_POINTS = 100_000
#: Largest number of axes a machine may have.
MAX_AXES = 16

JOB_ID_RE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
SEGMENT_KINDS = ("points", "bspline", "nurbs")
FITS = ("cubic", "pchip", "linear", "smooth")
STATES = ("idle", "running", "holding", "starved", "fault")
EVENT_TYPES = ("job_started", "job_finished", "rejected", "starved", "fault", "missing",
               "warning")
COMMANDS = ("hold", "resume", "abort", "override", "reset")
OVERRIDE_MAX = 1.5
#: smallest override taken: the planner plans to jmax * f^3, which for f much below this
#: underflows its checks (found by tests/test_service_fuzz.py: f = 1e-300 faulted a job)
OVERRIDE_MIN = 1e-3


class ProtocolError(ValueError):
    """A malformed message: `field` is the offending key (dotted/indexed), `reason` says why."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


# --- low-level helpers ---------------------------------------------------------------------


def _unpack(payload: bytes | bytearray | memoryview, max_bytes: int) -> dict[str, Any]:
    if not isinstance(payload, bytes | bytearray | memoryview):
        raise ProtocolError("payload", f"expected bytes, got {type(payload).__name__}")
    if len(payload) > max_bytes:
        raise ProtocolError("payload", f"{len(payload)} bytes exceeds the cap of {max_bytes}")
    try:
        obj = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=False,
                              max_bin_len=max_bytes, max_str_len=max_bytes,
                              max_array_len=max_bytes, max_map_len=max_bytes)
    except Exception as exc:  # msgpack raises several unrelated exception types
        reason = f"not valid MessagePack ({exc.__class__.__name__})"
        raise ProtocolError("payload", reason) from None
    if not isinstance(obj, dict):
        raise ProtocolError("payload", f"expected a map, got {type(obj).__name__}")
    if not all(isinstance(k, str) for k in obj):
        raise ProtocolError("payload", "map keys must be strings")
    return obj


def _pack(obj: dict[str, Any]) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def _require(msg: dict[str, Any], key: str) -> Any:
    if key not in msg:
        raise ProtocolError(key, "missing")
    return msg[key]


def _int(value: Any, name: str, lo: int | None = None, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ProtocolError(name, f"expected an integer, got {type(value).__name__}")
    if lo is not None and value < lo:
        raise ProtocolError(name, f"must be >= {lo}, got {value}")
    if hi is not None and value > hi:
        raise ProtocolError(name, f"must be <= {hi}, got {value}")
    return value


def _float(value: Any, name: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProtocolError(name, f"expected a number, got {type(value).__name__}")
    out = float(value)
    if not math.isfinite(out):
        raise ProtocolError(name, f"must be finite, got {out}")
    if positive and out <= 0:
        raise ProtocolError(name, f"must be > 0, got {out}")
    return out


def _bool(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise ProtocolError(name, f"expected true or false, got {type(value).__name__}")
    return value


def _str(value: Any, name: str) -> str:
    if not isinstance(value, str):
        raise ProtocolError(name, f"expected a string, got {type(value).__name__}")
    return value


def _job(value: Any, name: str = "job") -> str:
    job = _str(value, name)
    if not JOB_ID_RE.match(job):
        raise ProtocolError(name, f"must be 1..64 characters of A-Za-z0-9_.-, got {job[:80]!r}")
    return job


def _axes(value: Any, name: str = "axes") -> tuple[str, ...]:
    if not isinstance(value, list | tuple) or not value:
        raise ProtocolError(name, "expected a non-empty array of axis names")
    if len(value) > MAX_AXES:
        raise ProtocolError(name, f"at most {MAX_AXES} axes, got {len(value)}")
    names = tuple(_str(a, f"{name}[{i}]") for i, a in enumerate(value))
    if any(not a for a in names):
        raise ProtocolError(name, "axis names must be non-empty")
    if len(set(names)) != len(names):
        raise ProtocolError(name, f"axis names must be distinct, got {list(names)}")
    return names


def _vector(value: Any, name: str, length: int | None = None, max_len: int | None = None
            ) -> np.ndarray:
    """A plain array of finite numbers -> float64 vector."""
    if not isinstance(value, list | tuple):
        raise ProtocolError(name, f"expected an array of numbers, got {type(value).__name__}")
    if max_len is not None and len(value) > max_len:
        raise ProtocolError(name, f"{len(value)} entries exceeds the cap of {max_len}")
    if length is not None and len(value) != length:
        raise ProtocolError(name, f"expected {length} entries, got {len(value)}")
    for i, x in enumerate(value):
        if isinstance(x, bool) or not isinstance(x, int | float):
            raise ProtocolError(f"{name}[{i}]", f"expected a number, got {type(x).__name__}")
    arr = np.asarray(value, dtype=float)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ProtocolError(f"{name}[{bad[0]}]", f"must be finite, got {arr[bad[0]]}")
    return arr


def _matrix(value: Any, name: str, ncols: int, max_rows: int) -> np.ndarray:
    """A plain array of rows of `ncols` finite numbers -> float64 (n, ncols), n >= 1."""
    if not isinstance(value, list | tuple) or not value:
        raise ProtocolError(name, "expected a non-empty array of rows")
    if len(value) > max_rows:
        raise ProtocolError(name, f"{len(value)} rows exceeds the cap of {max_rows}")
    for i, row in enumerate(value):
        if not isinstance(row, list | tuple):
            raise ProtocolError(f"{name}[{i}]", f"expected a row of numbers, got "
                                f"{type(row).__name__}")
        if len(row) != ncols:
            raise ProtocolError(f"{name}[{i}]", f"expected {ncols} values (one per axis), "
                                f"got {len(row)}")
        for j, x in enumerate(row):
            if isinstance(x, bool) or not isinstance(x, int | float):
                raise ProtocolError(f"{name}[{i}][{j}]",
                                    f"expected a number, got {type(x).__name__}")
    arr = np.asarray(value, dtype=float)
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        i, j = bad[0]
        raise ProtocolError(f"{name}[{i}][{j}]", f"must be finite, got {arr[i, j]}")
    return arr


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


# --- segments ------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Segment:
    """One toolpath segment (NS/segments). Arrays are float64, rows are points in axis order.

    kind 'points': `points` (n, naxes) and `fit`; kind 'bspline'/'nurbs': `degree`, `knots`,
    `ctrl` (m, naxes) and, for nurbs, `weights` (m,). `feed` caps the path speed (path units/s).
    `tolerance` (path units, >= 0; None: the machine's default): how far fits `linear` and
    `smooth` may leave the points' polyline at this segment's points (0: exact stops).
    """

    job: str
    seq: int
    axes: tuple[str, ...]
    kind: str
    last: bool
    points: np.ndarray | None = None
    fit: str = "cubic"
    degree: int | None = None
    knots: np.ndarray | None = None
    ctrl: np.ndarray | None = None
    weights: np.ndarray | None = None
    feed: float | None = None
    tolerance: float | None = None

    def to_map(self) -> dict[str, Any]:
        out: dict[str, Any] = {"v": VERSION, "job": self.job, "seq": self.seq,
                               "axes": list(self.axes), "kind": self.kind, "last": self.last}
        if self.kind == "points":
            assert self.points is not None
            out["points"] = np.asarray(self.points, dtype=float).tolist()
            out["fit"] = self.fit
        else:
            assert self.ctrl is not None and self.knots is not None
            out["degree"] = self.degree
            out["knots"] = np.asarray(self.knots, dtype=float).tolist()
            out["ctrl"] = np.asarray(self.ctrl, dtype=float).tolist()
            if self.kind == "nurbs":
                assert self.weights is not None
                out["weights"] = np.asarray(self.weights, dtype=float).tolist()
        if self.feed is not None:
            out["feed"] = self.feed
        if self.tolerance is not None:
            out["tolerance"] = self.tolerance
        return out

    def encode(self) -> bytes:
        return _pack(self.to_map())

    @staticmethod
    def decode(payload: bytes, axes: tuple[str, ...] | list[str] | None = None) -> Segment:
        """Validate a segment payload. `axes`: the machine's axes the segment must name."""
        return validate_segment(_unpack(payload, MAX_PAYLOAD_BYTES), axes)


def _version(msg: dict[str, Any]) -> None:
    v = _int(_require(msg, "v"), "v")
    if v != VERSION:
        raise ProtocolError("v", f"unsupported protocol version {v}, expected {VERSION}")


def validate_segment(msg: dict[str, Any], axes: tuple[str, ...] | list[str] | None = None
                     ) -> Segment:
    """Validate an unpacked segment map (see `Segment.decode`)."""
    _version(msg)
    job = _job(_require(msg, "job"))
    seq = _int(_require(msg, "seq"), "seq", lo=0)
    seg_axes = _axes(_require(msg, "axes"))
    if axes is not None and tuple(axes) != seg_axes:
        raise ProtocolError("axes", f"must equal the machine's axes {list(axes)}, "
                            f"got {list(seg_axes)}")
    naxes = len(seg_axes)
    kind = _str(_require(msg, "kind"), "kind")
    if kind not in SEGMENT_KINDS:
        raise ProtocolError("kind", f"must be one of {', '.join(SEGMENT_KINDS)}, got {kind!r}")
    last = _bool(_require(msg, "last"), "last")
    feed = None
    if msg.get("feed") is not None:
        feed = _float(msg["feed"], "feed", positive=True)
    tolerance = None
    if msg.get("tolerance") is not None:
        tolerance = _float(msg["tolerance"], "tolerance")
        if tolerance < 0:
            raise ProtocolError("tolerance", f"must be >= 0, got {tolerance}")
    if kind == "points":
        points = _matrix(_require(msg, "points"), "points", naxes, MAX_SEGMENT_POINTS)
        fit = _str(msg.get("fit", "cubic"), "fit")
        if fit not in FITS:
            raise ProtocolError("fit", f"must be one of {', '.join(FITS)}, got {fit!r}")
        return Segment(job, seq, seg_axes, kind, last, points=_frozen(points), fit=fit,
                       feed=feed, tolerance=tolerance)
    degree = _int(_require(msg, "degree"), "degree", lo=1, hi=5)
    ctrl = _matrix(_require(msg, "ctrl"), "ctrl", naxes, MAX_SEGMENT_POINTS)
    m = ctrl.shape[0]
    if m < degree + 1:
        raise ProtocolError("ctrl", f"degree {degree} needs at least {degree + 1} control "
                            f"points, got {m}")
    knots = _vector(_require(msg, "knots"), "knots", max_len=MAX_SEGMENT_POINTS + 6)
    if knots.size != m + degree + 1:
        raise ProtocolError("knots", f"expected len(ctrl) + degree + 1 = {m + degree + 1} "
                            f"knots, got {knots.size}")
    dec = np.flatnonzero(np.diff(knots) < 0)
    if dec.size:
        raise ProtocolError(f"knots[{dec[0] + 1}]", "knots must be non-decreasing")
    if np.any(knots[: degree + 1] != knots[0]) or np.any(knots[-degree - 1:] != knots[-1]):
        raise ProtocolError("knots", f"must be clamped: the first and the last {degree + 1} "
                            "knots must be equal")
    if knots[-1] <= knots[0]:
        raise ProtocolError("knots", "the knot span must have positive length")
    weights = None
    if kind == "nurbs":
        weights = _vector(_require(msg, "weights"), "weights", length=m)
        bad = np.flatnonzero(weights <= 0)
        if bad.size:
            raise ProtocolError(f"weights[{bad[0]}]", f"must be > 0, got {weights[bad[0]]}")
        weights = _frozen(weights)
    return Segment(job, seq, seg_axes, kind, last, degree=degree, knots=_frozen(knots),
                   ctrl=_frozen(ctrl), weights=weights, feed=feed, tolerance=tolerance)


# --- setpoints -----------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class SetpointBatch:
    """A batch of n samples (NS/setpoints); sample k0 + i is due at (k0 + i) * dt after start.

    pos, vel, acc: float64 (n, naxes) in axis units (mm, deg) and per second, per second^2.
    applied: our extension: (job, seq) of the segments the service took in just before it
    produced this batch (so a recorder knows the sample index k0 at which each segment was
    received, and a replay can feed them at the same indices).
    commands: our extension: (verb, value, after) of the commands the service applied just
    before it produced this batch, in order; `after` = how many of `applied` it had taken
    in before the command (a replay interleaves them exactly).
    dropped: our extension: the sample indices k_at (this job) of replans computed ahead
    that the service dropped just before it produced this batch, because they were not
    done when their take-over was due (real time; the plan in force went on; a replay
    drops them too).
    """

    job: str
    seq: int
    k0: int
    dt: float
    axes: tuple[str, ...]
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    final: bool
    applied: tuple[tuple[str, int], ...] = ()
    commands: tuple[tuple[str, float | None, int], ...] = ()
    dropped: tuple[int, ...] = ()

    @property
    def n(self) -> int:
        return int(self.pos.shape[0])

    def encode(self) -> bytes:
        def blob(a: np.ndarray) -> bytes:
            return np.ascontiguousarray(a, dtype="<f8").tobytes()

        return _pack({"v": VERSION, "job": self.job, "seq": self.seq, "k0": self.k0,
                      "dt": self.dt, "axes": list(self.axes), "n": self.n,
                      "pos": blob(self.pos), "vel": blob(self.vel), "acc": blob(self.acc),
                      "final": self.final,
                      "applied": [[job, seq] for job, seq in self.applied],
                      "commands": [[verb, value, after] for verb, value, after in self.commands],
                      **({"dropped": list(self.dropped)} if self.dropped else {})})

    @staticmethod
    def decode(payload: bytes) -> SetpointBatch:
        msg = _unpack(payload, 1 << 30)
        _version(msg)
        job = _job(_require(msg, "job"))
        seq = _int(_require(msg, "seq"), "seq", lo=0)
        k0 = _int(_require(msg, "k0"), "k0", lo=0)
        dt = _float(_require(msg, "dt"), "dt", positive=True)
        axes = _axes(_require(msg, "axes"))
        n = _int(_require(msg, "n"), "n", lo=0)
        final = _bool(_require(msg, "final"), "final")
        arrays = []
        for name in ("pos", "vel", "acc"):
            raw = _require(msg, name)
            if not isinstance(raw, bytes):
                raise ProtocolError(name, f"expected bin, got {type(raw).__name__}")
            if len(raw) != n * len(axes) * 8:
                raise ProtocolError(name, f"expected {n * len(axes) * 8} bytes "
                                    f"(n={n} x {len(axes)} axes x 8), got {len(raw)}")
            arrays.append(np.frombuffer(raw, dtype="<f8").reshape(n, len(axes)))
        applied = _applied(msg.get("applied", []))
        commands = _commands(msg.get("commands", []), len(applied))
        dropped = msg.get("dropped", [])
        if not isinstance(dropped, list):
            raise ProtocolError("dropped", "expected an array of sample indices")
        dropped = tuple(_int(k, "dropped", lo=0) for k in dropped)
        return SetpointBatch(job, seq, k0, dt, axes, *arrays, final=final, applied=applied,
                             commands=commands, dropped=dropped)


def _applied(value: Any) -> tuple[tuple[str, int], ...]:
    if not isinstance(value, list | tuple):
        raise ProtocolError("applied", "expected an array of [job, seq] pairs")
    out = []
    for i, item in enumerate(value):
        if not isinstance(item, list | tuple) or len(item) != 2:
            raise ProtocolError(f"applied[{i}]", "expected a [job, seq] pair")
        out.append((_job(item[0], f"applied[{i}][0]"), _int(item[1], f"applied[{i}][1]", lo=0)))
    return tuple(out)


def _commands(value: Any, n_applied: int) -> tuple[tuple[str, float | None, int], ...]:
    if not isinstance(value, list | tuple):
        raise ProtocolError("commands", "expected an array of [verb, value, after] triples")
    out = []
    for i, item in enumerate(value):
        where = f"commands[{i}]"
        if not isinstance(item, list | tuple) or len(item) != 3:
            raise ProtocolError(where, "expected a [verb, value, after] triple")
        verb = _str(item[0], f"{where}[0]")
        if verb not in COMMANDS:
            raise ProtocolError(f"{where}[0]", f"must be one of {', '.join(COMMANDS)}, "
                                f"got {verb!r}")
        val = None if item[1] is None else _float(item[1], f"{where}[1]")
        out.append((verb, val, _int(item[2], f"{where}[2]", lo=0, hi=n_applied)))
    return tuple(out)


# --- status, events, commands -------------------------------------------------------------


@dataclass(frozen=True)
class Status:
    """The service's state (NS/status)."""

    state: str
    job: str | None
    k: int
    queued: int
    horizon_s: float
    override: float
    planner: str
    plan_ms: float
    error: str | None = None
    #: flow control (PROTOCOL.md "Delivery"): the job being received, its lowest seq not
    #: yet received (last + 1 once its `last` segment is in), points and control points
    #: received but not executed, false while the service's buffer is full
    receiving: str | None = None
    next_seq: int | None = None
    buffered_points: int = 0
    accepting: bool = True
    #: window plans the configured planner could not make (the stop planner made them)
    fallbacks: int = 0
    #: ours (absent in older messages): true when the committed plan runs to the end of
    #: the job (all segments in, the last window planned to the final stop, or the stop
    #: of an abort/fault); then `remaining_s` is the exact motion time (s) from sample `k`
    #: to the job's last sample at the current override, else None (`horizon_s` is then
    #: only the plan to its next stop). Holds are not counted; an override or hold command
    #: voids it until the plan is remade (`lookahead.stream.engine`, "Time left").
    plan_complete: bool = False
    remaining_s: float | None = None

    def encode(self) -> bytes:
        return _pack({"v": VERSION, "state": self.state, "job": self.job, "k": self.k,
                      "queued": self.queued, "horizon_s": self.horizon_s,
                      "override": self.override, "planner": self.planner,
                      "plan_ms": self.plan_ms, "error": self.error,
                      "receiving": self.receiving, "next_seq": self.next_seq,
                      "buffered_points": self.buffered_points, "accepting": self.accepting,
                      "fallbacks": self.fallbacks, "plan_complete": self.plan_complete,
                      "remaining_s": self.remaining_s})

    @staticmethod
    def decode(payload: bytes) -> Status:
        msg = _unpack(payload, 1 << 20)
        state = _str(_require(msg, "state"), "state")
        if state not in STATES:
            raise ProtocolError("state", f"must be one of {', '.join(STATES)}, got {state!r}")
        job = _require(msg, "job")
        job = None if job is None else _job(job)
        error = _require(msg, "error")
        error = None if error is None else _str(error, "error")
        # flow-control fields: absent in older recordings, so read with defaults
        receiving = msg.get("receiving")
        receiving = None if receiving is None else _job(receiving, "receiving")
        next_seq = msg.get("next_seq")
        next_seq = None if next_seq is None else _int(next_seq, "next_seq", lo=0)
        # time-left fields: absent in older messages (plan_complete false, remaining nil)
        remaining = msg.get("remaining_s")
        remaining = None if remaining is None else _float(remaining, "remaining_s")
        if remaining is not None and remaining < 0:
            raise ProtocolError("remaining_s", f"must be >= 0 or nil, got {remaining!r}")
        return Status(state, job, _int(_require(msg, "k"), "k"),
                      _int(_require(msg, "queued"), "queued", lo=0),
                      _float(_require(msg, "horizon_s"), "horizon_s"),
                      _float(_require(msg, "override"), "override"),
                      _str(_require(msg, "planner"), "planner"),
                      _float(_require(msg, "plan_ms"), "plan_ms"), error,
                      receiving, next_seq,
                      _int(msg.get("buffered_points", 0), "buffered_points", lo=0),
                      _bool(msg.get("accepting", True), "accepting"),
                      _int(msg.get("fallbacks", 0), "fallbacks", lo=0),
                      _bool(msg.get("plan_complete", False), "plan_complete"), remaining)


@dataclass(frozen=True)
class Event:
    """One event (NS/events). `extra` holds the type's own fields (duration_s, aborted, seq,
    reason, ...), flattened into the map on the wire."""

    type: str
    job: str | None
    k: int
    extra: dict[str, Any] = field(default_factory=dict)

    def encode(self) -> bytes:
        return _pack({**self.extra, "v": VERSION, "type": self.type, "job": self.job,
                      "k": self.k})

    @staticmethod
    def decode(payload: bytes) -> Event:
        msg = _unpack(payload, 1 << 20)
        etype = _str(_require(msg, "type"), "type")
        if etype not in EVENT_TYPES:
            raise ProtocolError("type", f"must be one of {', '.join(EVENT_TYPES)}, "
                                f"got {etype!r}")
        job = _require(msg, "job")
        job = None if job is None else _str(job, "job")
        k = _int(_require(msg, "k"), "k")
        extra = {key: val for key, val in msg.items() if key not in ("v", "type", "job", "k")}
        if etype == "rejected":
            _str(_require(msg, "reason"), "reason")
        if etype == "missing":
            _int(_require(msg, "seq"), "seq", lo=0)
        if etype in ("fault", "warning"):
            _str(_require(msg, "reason"), "reason")
        if etype == "job_finished":
            _float(_require(msg, "duration_s"), "duration_s")
        return Event(etype, job, k, extra)


@dataclass(frozen=True)
class CommandReply:
    """Reply to a `get` on NS/cmd/<verb>."""

    ok: bool
    error: str | None = None

    def encode(self) -> bytes:
        out: dict[str, Any] = {"ok": self.ok}
        if not self.ok:
            out["error"] = self.error or "failed"
        return _pack(out)

    @staticmethod
    def decode(payload: bytes) -> CommandReply:
        msg = _unpack(payload, 1 << 20)
        ok = _bool(_require(msg, "ok"), "ok")
        error = None if ok else _str(_require(msg, "error"), "error")
        return CommandReply(ok, error)


@dataclass(frozen=True)
class Command:
    """A command request: `verb` from the key NS/cmd/<verb>, `value` for override."""

    verb: str
    value: float | None = None

    def encode(self) -> bytes:
        return _pack({} if self.value is None else {"value": self.value})

    @staticmethod
    def decode(verb: str, payload: bytes | None) -> Command:
        if verb not in COMMANDS:
            raise ProtocolError("verb", f"must be one of {', '.join(COMMANDS)}, got {verb!r}")
        msg = _unpack(payload, 1 << 16) if payload else {}
        if verb != "override":
            return Command(verb)
        value = _float(_require(msg, "value"), "value")
        if not OVERRIDE_MIN <= value <= OVERRIDE_MAX:
            raise ProtocolError("value", f"override must be in [{OVERRIDE_MIN}, {OVERRIDE_MAX}] "
                                f"(0 < f, and the planner needs f^3 > 0), got {value}")
        return Command(verb, value)


def key(ns: str, *parts: str) -> str:
    """Key expression under the namespace, e.g. key(ns, 'cmd', 'hold')."""
    return "/".join((ns, *parts))
