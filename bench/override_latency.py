"""How long an override holds up the samples in real time (the bridge of
`Engine._commit_command`, A/B against planning the override with the configured planner at
once).

In real time the service publishes ahead of the machine by a buffer of 50 ms plus 1.5x the
slowest batch computation seen (at most ~1 s); a batch computation longer than what is
buffered starves the machine. Per corpus path and variant: a real-time engine with a worker
thread (as `lookahead serve`) runs the path with the LP; at seeded random samples of the
motion an override is sent (alternating 0.6 and 1.0); the wall time of the `command()`
call plus the `next_batch()` calls until 0.1 s of motion after it is recorded, and its
longest single call ("block": what the machine's buffer must cover). The whole stream is
judged by the finite-difference checker. Both variants run the same commands at the same
samples, one after the other in one process (compute times share the machine's load).

    .venv/bin/python bench/override_latency.py [--paths GLOB,...] [--overrides 6] [--seed 1]
        [--variants at_once,bridged]

Results: bench/results/override_latency.json.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path as FsPath

import numpy as np

ROOT = FsPath(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.corpus import load_corpus  # noqa: E402
from lookahead.checker import LimitChecker  # noqa: E402
from lookahead.protocol import Command  # noqa: E402
from lookahead.stream.engine import Engine  # noqa: E402
from lookahead.stream.planners import make_planner  # noqa: E402

OUT = ROOT / "bench" / "results" / "override_latency.json"
DEFAULT_PATHS = ("w-issue-tube1450-*", "w-hoop-*", "cam-style-*", "c-corners-*",
                 "c-fourier-*", "n-butterfly")
#: motion after an override over which the calls are timed (s)
AFTER_S = 0.1
#: engine calls without a batch before a job counts as stuck
MAX_IDLE = 200_000


def run(p, bridge: bool, at: list[int]) -> dict:
    """The path through a real-time LP engine with a worker, overrides at samples `at`."""
    cfg = p.config
    dt = cfg.machine.dt
    after = round(AFTER_S / dt)
    checker = LimitChecker(cfg.machine.limits, dt)
    blocks, totals = [], []  # per override: longest call, all calls until AFTER_S (s)
    with ThreadPoolExecutor(max_workers=1) as pool:
        engine = Engine(cfg, make_planner("lp"), realtime=True, executor=pool)
        engine.bridge_overrides = bridge
        for seg in p.segments:
            engine.submit(seg)
        todo = list(at)
        k, idle, finished = 0, 0, False
        timed: dict | None = None  # the override being timed
        t_start = time.perf_counter()
        while idle < MAX_IDLE:
            if todo and k >= todo[0]:
                todo.pop(0)
                t0 = time.perf_counter()
                engine.command(Command("override", 0.6 if len(todo) % 2 == 0 else 1.0))
                spent = time.perf_counter() - t0
                timed = {"total": spent, "block": spent, "until": k + after}
            t0 = time.perf_counter()
            batch = engine.next_batch()
            spent = time.perf_counter() - t0
            if timed is not None:
                timed["total"] += spent
                timed["block"] = max(timed["block"], spent)
                if k >= timed["until"]:
                    blocks.append(timed["block"])
                    totals.append(timed["total"])
                    timed = None
            if batch is None:
                idle += 1
                if not engine.busy:
                    break
                continue
            idle = 0
            checker.feed(batch.pos)
            k = batch.k0 + batch.n
            if batch.final:
                finished = True
                break
        wall = time.perf_counter() - t_start
    rep = checker.report()
    return {"finished": finished, "overrides": len(totals), "violations": rep.violations,
            "fallbacks": engine.fallbacks, "replan_failures": engine.replan_failures,
            "handovers": engine.handovers, "bridges": engine.bridges,
            "takeover_waits": engine.takeover_waits, "motion_s": k * dt, "wall_s": wall,
            "block_ms": [1e3 * b for b in blocks],
            "after_ms": [1e3 * t for t in totals]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--paths", default=",".join(DEFAULT_PATHS))
    ap.add_argument("--overrides", type=int, default=6)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--variants", default="at_once,bridged",
                    help="comma-separated: at_once, bridged")
    args = ap.parse_args()
    globs = args.paths.split(",")
    out: dict = {"meta": {"overrides": args.overrides, "seed": args.seed,
                          "after_s": AFTER_S}, "paths": {}}
    for p in load_corpus("fast", skip_long=True):
        if not any(fnmatch.fnmatch(p.name, g) for g in globs):
            continue
        probe = run(p, True, [])  # the motion's length, to place the overrides in it
        n = round(probe["motion_s"] / p.config.machine.dt)
        rng = np.random.default_rng(args.seed)
        at = sorted(int(x) for x in rng.integers(n // 20, int(0.8 * n), args.overrides))
        row = out["paths"][p.name] = {}
        for variant, bridge in (("at_once", False), ("bridged", True)):
            if variant not in args.variants.split(","):
                continue
            r = row[variant] = run(p, bridge, at)
            print(f"{p.name:40s} {variant:8s} block max {max(r['block_ms'], default=0):7.1f} "
                  f"ms  median {np.median(r['block_ms']) if r['block_ms'] else 0:6.1f} ms  "
                  f"viol {r['violations']} fallbacks {r['fallbacks']} failures "
                  f"{r['replan_failures']} handovers {r['handovers']} waits "
                  f"{r['takeover_waits']}", file=sys.stderr, flush=True)
    FsPath(args.out).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
