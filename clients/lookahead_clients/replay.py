"""`lookahead replay FILE`: feed a recording's segments to a fresh service `Engine` at the
sample indices where the service took them in, and compare the setpoints it produces with
the recorded ones, batch by batch.

For each recorded setpoint batch, in order: submit the segments its `applied` list names
(their recorded payloads) and apply the commands (hold, override, ...) its `commands` list
names, in the order the service took them in, then ask the engine for batches until it
returns one, and compare job, seq, k0, n, final and the pos/vel/acc arrays. The engine runs
as the recorded service did, `--fast` or in real time (`--mode`; by default it tries both).
Exit 0 if every batch matches (within `--tolerance`).

Bit-identical is the default only under the software the recording was made with (its
header's `software`): another numpy, scipy or ruckig rounds differently in the last bits,
so a recording from elsewhere is compared within `FOREIGN_TOLERANCE`, and replay says so.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field

#: engine calls without a batch before a recorded batch counts as missing
MAX_IDLE_CALLS = 100_000
#: default tolerance (mm, deg and their per-second derivatives) for a recording made under
#: other software versions; measured between numpy/scipy releases: 3e-8 (acc, mm/s^2)
FOREIGN_TOLERANCE = 1e-6


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
                        "bit-identical, under the recording's software versions, else "
                        f"{FOREIGN_TOLERANCE:g})")
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
    tolerance = args.tolerance
    if tolerance is None:
        tolerance = default_tolerance(rec.header.get("software"))
    mode = "realtime" if args.realtime else args.mode
    # the modes differ only while holding or starved (real time keeps emitting rest
    # samples), so a recording without either matches both
    res, realtime = None, False
    for rt in {"auto": (False, True), "fast": (False,), "realtime": (True,)}[mode]:
        trial = replay(rec, cfg, realtime=rt, tolerance=tolerance)
        if res is None or trial.matched > res.matched:  # neither matches: the closer one
            res, realtime = trial, rt
        if trial.identical:
            break
    if mode == "auto" and realtime:
        print("replay: " + ("matched" if res.identical else "compared") +
              " as a real-time service's recording")
    print(f"replay: {res.batches} batches of {len(res.jobs)} job(s) ({res.segments} segments, "
          f"{res.commands} commands): "
          f"{res.matched} matched, max |difference| {res.max_diff:.3g}")
    if res.first_mismatch:
        print(f"replay: first mismatch: {res.first_mismatch}")
    return 0 if res.identical else 1


def default_tolerance(recorded: dict | None) -> float:
    """0 (bit-identical) if `recorded` (a header's `software`) is this environment's, else
    `FOREIGN_TOLERANCE`, with a note on stdout naming what differs."""
    from lookahead_clients.recording import software_versions

    here = software_versions()
    if recorded == here:
        return 0.0
    if not isinstance(recorded, dict):
        what = "no software versions (an older recording)"
    else:
        what = ", ".join(f"{k} {recorded.get(k, '?')} (here {v})" for k, v in here.items()
                         if recorded.get(k) != v)
    print(f"replay: the recording names {what}: comparing within {FOREIGN_TOLERANCE:g} "
          "(--tolerance 0 for bit-identical)")
    return FOREIGN_TOLERANCE


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
    import numpy as np

    if a.shape != b.shape:
        return float("inf")
    if np.array_equal(a, b):
        return 0.0
    return float(np.max(np.abs(a - b)))


def replay(rec, cfg, realtime: bool = False, tolerance: float = 0.0) -> ReplayResult:
    """Replay `rec` (a `Recording`) into a fresh Engine planning with `cfg`."""
    from lookahead.protocol import Command, ProtocolError, Segment, SetpointBatch
    from lookahead.stream.engine import Engine
    from lookahead.stream.planners import make_planner

    engine = Engine(cfg, make_planner(cfg.planner.method), realtime=realtime)
    segments: dict[tuple[str, int], bytes] = {}
    for r in rec.samples("segments"):
        try:
            seg = Segment.decode(r["payload"])
        except ProtocolError:
            continue  # the service rejected it without taking it in
        segments.setdefault((seg.job, seg.seq), r["payload"])
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
            engine.submit(Segment.decode(payload))
            res.segments += 1
        got = None
        for _ in range(MAX_IDLE_CALLS):
            got = engine.next_batch()
            if got is not None:
                break
        where = f"batch {want.job}/{want.seq} (k0 {want.k0})"
        if got is None:
            res.first_mismatch = res.first_mismatch or f"{where}: the engine produced none"
            break
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
    return res
