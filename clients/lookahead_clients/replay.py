"""`lookahead replay FILE`: feed a recording's segments to a fresh service `Engine` at the
sample indices where the service took them in, and compare the setpoints it produces with
the recorded ones, batch by batch.

For each recorded setpoint batch, in order: submit the segments its `applied` list names
(their recorded payloads) and apply the commands (hold, override, ...) its `commands` list
names, in the order the service took them in, mark the replans computed ahead that its
`dropped` list names (the real-time service dropped them as late), then ask the engine for
batches until it returns one, and compare job, seq, k0, n, final and the pos/vel/acc
arrays. The engine runs as the recorded service did, `--fast` or in real time (`--mode`;
by default it tries both). Exit 0 if every batch matches (within `--tolerance`).

What replay promises: bit-identical on the machine that made the recording, i.e. under the
same software versions (header `software`) AND the same floating-point environment (header
`fp_env`: CPU, SIMD features, BLAS build and threads), because numpy's OpenBLAS, scipy and
HiGHS pick their SIMD kernels by CPU and the same versions round differently elsewhere.
Anywhere else the setpoints are compared within `FOREIGN_TOLERANCE` and replay says so
("matched within 0.01: different CPU"); that still exits 0. A last-bit difference can also
turn a planning decision (a verification at its limit, a repair round) the other way, after
which the streams part by millimetres: on another machine that is reported as "diverged"
with exit 4 (`EXIT_DIVERGED`), together with the independent limit check of the replayed
setpoints (a replayed stream over a limit exits 1). On the recording's own machine any
difference exits 1.

`--perturb REL` multiplies every recorded segment coordinate by (1 +- REL) before
replaying: how far a last-bit difference of the inputs grows through the engine, the
measurement `FOREIGN_TOLERANCE` is derived from (`bench/replay_tolerance.py`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

#: exit status of a replay on another machine whose streams parted (see the module docstring)
EXIT_DIVERGED = 4
#: engine calls without a batch before a recorded batch counts as missing
MAX_IDLE_CALLS = 100_000
#: tolerance (axis units and their per-second derivatives) for a recording made in another
#: floating-point environment. Derived, not guessed (bench/replay_tolerance.py, results in
#: bench/results/replay_tolerance.json): every input coordinate of the golden recording and
#: of LP and heuristic recordings of both presets moved by one ulp (more than another CPU's
#: BLAS, LAPACK, HiGHS or SIMD kernels change a result), 4 seeds, in the runs where no
#: planning decision flipped (those replay reports as "diverged"), moved the setpoints by at
#: most `worst_smooth_at_basis` there (7.4e-4, the heuristic on tube-9570, acceleration);
#: times a safety factor of 10, rounded up to a power of ten. Seen in the field (same
#: versions, another CPU): 3.3e-8.
FOREIGN_TOLERANCE = 1e-2


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", help="recording written by `lookahead record`")
    p.add_argument("--config", help="plan with this configuration instead of the recorded one")
    p.add_argument("--mode", choices=("auto", "fast", "realtime"), default="auto",
                   help="how the recorded service ran: `serve --fast` or in real time "
                        "(default auto: fast, then real time if that does not match)")
    p.add_argument("--realtime", action="store_true", help="the same as --mode realtime")
    p.add_argument("--tolerance", type=float, default=None,
                   help="largest accepted |difference| of pos/vel/acc (default: 0, i.e. "
                        "bit-identical, on the machine and software the recording names, "
                        f"else {FOREIGN_TOLERANCE:g})")
    p.add_argument("--perturb", type=float, default=0.0, metavar="REL",
                   help="multiply every segment coordinate by (1 +- REL) first (a "
                        "sensitivity measurement; a nonzero REL compares within --tolerance, "
                        "default inf: reports the difference only)")
    return p


@dataclass
class ReplayResult:
    """Batches compared, how many matched, the largest difference, the first mismatch."""

    batches: int = 0
    matched: int = 0
    segments: int = 0
    commands: int = 0
    max_diff: float = 0.0
    first_mismatch: str | None = None
    jobs: list[str] = field(default_factory=list)
    #: the independent limit check of the setpoints the replay produced, all jobs
    violations: int = 0

    @property
    def identical(self) -> bool:
        return self.batches > 0 and self.matched == self.batches


def run(args: argparse.Namespace) -> int:
    from lookahead.config import build_config, load_config_or_exit
    from lookahead_clients.recording import RecordingError, read_recording

    try:
        rec = read_recording(args.file)
    except (OSError, RecordingError) as exc:
        print(f"replay: {exc}", file=sys.stderr)
        return 2
    if args.config:
        cfg = load_config_or_exit(args.config)
    else:
        import tomllib

        cfg = build_config(tomllib.loads(rec.header["config_toml"]), f"{args.file} (header)")
    tolerance, why = args.tolerance, "--tolerance"
    if args.perturb:
        tolerance, why = (float("inf") if tolerance is None else tolerance), "perturbed"
    elif tolerance is None:
        tolerance, why = default_tolerance(rec.header)
    mode = "realtime" if args.realtime else args.mode
    # the modes differ only while holding or starved (real time keeps emitting rest
    # samples), so a recording without either matches both
    res, realtime = None, False
    for rt in {"auto": (False, True), "fast": (False,), "realtime": (True,)}[mode]:
        trial = replay(rec, cfg, realtime=rt, tolerance=tolerance, perturb=args.perturb)
        if res is None or trial.matched > res.matched:  # neither matches: the closer one
            res, realtime = trial, rt
        if trial.identical:
            break
    if mode == "auto" and realtime:
        print("replay: " + ("matched" if res.identical else "compared") +
              " as a real-time service's recording")
    how = "bit-identically" if tolerance == 0 else f"within {tolerance:g}: {why}"
    print(f"replay: {res.batches} batches of {len(res.jobs)} job(s) ({res.segments} segments, "
          f"{res.commands} commands): "
          f"{res.matched} matched {how}, max |difference| {res.max_diff:.3g}")
    if res.first_mismatch:
        print(f"replay: first mismatch: {res.first_mismatch}")
    print(f"replay: the replayed setpoints: {res.violations} limit violations "
          "(finite-difference check)")
    if res.violations:
        return 1
    if res.identical:
        return 0
    if args.tolerance is None and not args.perturb and tolerance > 0:
        print("replay: diverged: a planning decision went the other way in the last bits "
              "on this machine; both streams are valid plans, they cannot be compared "
              "sample by sample here (replay on the recording's machine for bit-identity)")
        return EXIT_DIVERGED
    return 1


def default_tolerance(header: dict) -> tuple[float, str]:
    """(0, "same machine") if the recording's header names this environment's software and
    floating-point environment, else (`FOREIGN_TOLERANCE`, what differs), with a note on
    stdout."""
    from lookahead_clients.recording import floating_point_environment, software_versions

    differs = []
    for key, label, here in (("software", "other software", software_versions()),
                             ("fp_env", "different CPU", floating_point_environment())):
        recorded = header.get(key)
        if not isinstance(recorded, dict):
            differs.append(f"{label} (the recording does not name its {key})")
        elif recorded != here:
            what = ", ".join(f"{k} {recorded.get(k, '?')!s} (here {v!s})"
                             for k, v in here.items() if recorded.get(k) != v)
            differs.append(f"{label}: {what}")
    if not differs:
        return 0.0, "same machine"
    print(f"replay: recorded elsewhere, {'; '.join(differs)}: comparing within "
          f"{FOREIGN_TOLERANCE:g} (--tolerance 0 for bit-identical)")
    return FOREIGN_TOLERANCE, " and ".join(d.split(" (")[0].split(":")[0] for d in differs)


def batch_inputs(batch) -> Iterator:
    """What the service took in before producing `batch` (a SetpointBatch), in its order:
    the (job, seq) of each `applied` segment and a Command for each of its `commands`."""
    from lookahead.protocol import Command

    for i in range(len(batch.applied) + 1):
        for verb, value, after in batch.commands:
            if after == i:
                yield Command(verb, value)
        if i < len(batch.applied):
            yield batch.applied[i]


def _max_diff(a, b) -> float:
    if a.shape != b.shape:
        return float("inf")
    if np.array_equal(a, b):
        return 0.0
    return float(np.max(np.abs(a - b)))


def record_engine(cfg, segments, fh, realtime: bool = False, feed_every: int = 0,
                  started_unix: float = 0.0) -> int:
    """Write a recording (`lookahead record`'s format) of a fresh Engine planning `segments`
    (Segments of one or more jobs) with `cfg`, without a bus: what a `serve --fast` service
    would have published, on this machine. With `feed_every` > 0 the segments are taken in
    one per that many batches (as a paced publisher's), else all before the first batch.
    Returns the number of setpoint batches written."""
    from lookahead.config import config_to_toml
    from lookahead.protocol import key
    from lookahead.stream.engine import Engine
    from lookahead.stream.planners import make_planner
    from lookahead_clients.recording import RecordingWriter

    writer = RecordingWriter(fh, cfg.ns, config_to_toml(cfg), started_unix)
    engine = Engine(cfg, make_planner(cfg.planner.method), realtime=realtime)
    pending, batches, idle, t = list(segments), 0, 0, 0.0

    def take_in(n: int) -> None:
        for seg in pending[:n]:
            writer.sample(t, key(cfg.ns, "segments"), "put", seg.encode())
            engine.submit(seg)
        del pending[:n]

    take_in(len(pending) if feed_every <= 0 else 1)
    while idle < MAX_IDLE_CALLS:
        batch = engine.next_batch()
        if batch is None:
            if not pending:
                idle += 1
            take_in(1)
            continue
        idle, t, batches = 0, t + batch.n * batch.dt, batches + 1
        writer.sample(t, key(cfg.ns, "setpoints"), "put", batch.encode())
        if feed_every > 0 and batches % feed_every == 0:
            take_in(1)
        if batch.final and not pending and not engine.busy:
            break
    return batches


def perturbed(seg, rel: float, rng):
    """`seg` (a Segment) with every coordinate (points, ctrl) multiplied by 1 +- `rel`
    (random signs from `rng`, a numpy Generator)."""
    import dataclasses

    changes = {}
    for name in ("points", "ctrl"):
        arr = getattr(seg, name)
        if arr is not None:
            arr = np.asarray(arr, dtype=float)
            changes[name] = arr * (1.0 + rel * rng.choice((-1.0, 1.0), size=arr.shape))
    return dataclasses.replace(seg, **changes)


def replay(rec, cfg, realtime: bool = False, tolerance: float = 0.0, perturb: float = 0.0,
           seed: int = 0) -> ReplayResult:
    """Replay `rec` (a `Recording`) into a fresh Engine planning with `cfg`; with `perturb`,
    every segment coordinate is first multiplied by 1 +- `perturb` (seeded by `seed`)."""
    from lookahead.checker import LimitChecker
    from lookahead.protocol import Command, ProtocolError, Segment, SetpointBatch
    from lookahead.stream.engine import Engine
    from lookahead.stream.planners import make_planner

    engine = Engine(cfg, make_planner(cfg.planner.method), realtime=realtime)
    checkers: dict[str, LimitChecker] = {}
    segments: dict[tuple[str, int], bytes] = {}
    for r in rec.samples("segments"):
        try:
            seg = Segment.decode(r["payload"])
        except ProtocolError:
            continue  # the service rejected it without taking it in
        segments.setdefault((seg.job, seg.seq), r["payload"])
    rng = np.random.default_rng(seed)
    res = ReplayResult()
    for r in rec.samples("setpoints"):
        want = SetpointBatch.decode(r["payload"])
        res.batches += 1
        if want.job not in res.jobs:
            res.jobs.append(want.job)
        for item in batch_inputs(want):
            if isinstance(item, Command):
                engine.command(item)
                res.commands += 1
                continue
            payload = segments.get(item)
            if payload is None:
                res.first_mismatch = res.first_mismatch or \
                    f"segment {item[0]}/{item[1]} is listed as applied but was not recorded"
                continue
            seg = Segment.decode(payload)
            engine.submit(perturbed(seg, perturb, rng) if perturb else seg)
            res.segments += 1
        for k_at in want.dropped:  # replans the recorded service dropped as late
            engine.drop_replan(want.job, k_at)
        got = None
        for _ in range(MAX_IDLE_CALLS):
            got = engine.next_batch()
            if got is not None:
                break
        where = f"batch {want.job}/{want.seq} (k0 {want.k0})"
        if got is None:
            res.first_mismatch = res.first_mismatch or f"{where}: the engine produced none"
            break
        checker = checkers.setdefault(got.job, LimitChecker(cfg.machine.limits, got.dt))
        checker.feed(got.pos)
        same_header = (got.job, got.seq, got.k0, got.n, got.final) == \
            (want.job, want.seq, want.k0, want.n, want.final)
        diff = max(_max_diff(got.pos, want.pos), _max_diff(got.vel, want.vel),
                   _max_diff(got.acc, want.acc)) if same_header else float("inf")
        res.max_diff = max(res.max_diff, diff)
        if same_header and diff <= tolerance:
            res.matched += 1
        elif res.first_mismatch is None:
            res.first_mismatch = (
                f"{where}: got {got.job}/{got.seq} k0 {got.k0} n {got.n} final {got.final}, "
                f"max |difference| {diff:.3g}")
    res.violations = sum(c.report().violations for c in checkers.values())
    return res
