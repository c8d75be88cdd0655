"""How long a hold holds up the samples in real time, and how far the machine runs on:
the plan in force re-timed to rest (`Engine._warp_stop` through `_retimed`) A/B against
the shortest-stop search (`plans.shortest_stop`, bisection with the heuristic).

In real time the service publishes ahead of the machine by a buffer of 50 ms plus 1.5x the
slowest batch computation seen (at most ~1 s); a batch computation longer than what is
buffered starves the machine. Per corpus path and variant: a real-time engine with a worker
thread (as `lookahead serve`) runs the path with the LP; at seeded random samples of the
motion a `hold` is sent, each by a fresh engine run to that sample (so both variants stop
from the same state). Per hold: the longest single engine call (`command()` and the
`next_batch()` calls) until 0.1 s of motion after it ("block": what the buffer must cover)
and the stop distance (path length from the last sample before the hold to the rest
point); the stream to the rest point is judged by the finite-difference checker.

    .venv/bin/python bench/stop_latency.py [--paths GLOB,...] [--holds 6] [--seed 1]

Results: bench/results/stop_latency.json.
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
from bench.override_latency import AFTER_S, DEFAULT_PATHS, MAX_IDLE  # noqa: E402
from lookahead.checker import LimitChecker  # noqa: E402
from lookahead.protocol import Command  # noqa: E402
from lookahead.stream.engine import Engine  # noqa: E402
from lookahead.stream.planners import make_planner  # noqa: E402

OUT = ROOT / "bench" / "results" / "stop_latency.json"


def hold_once(p, retime: bool, k_hold: int) -> dict:
    """A fresh real-time LP engine with a worker runs the path to sample `k_hold` (the same
    batches for both variants: the engine is deterministic), then a hold: the longest
    engine call until AFTER_S of motion after it, the stop distance, whether the stream to
    the rest point passes the checker."""
    cfg = p.config
    dt = cfg.machine.dt
    checker = LimitChecker(cfg.machine.limits, dt)
    with ThreadPoolExecutor(max_workers=1) as pool:
        engine = Engine(cfg, make_planner("lp"), realtime=True, executor=pool)
        engine.warp_stops = retime
        for seg in p.segments:
            engine.submit(seg)
        k, idle, block, s_cmd, s_rest, rest_k = 0, 0, 0.0, None, None, None
        while idle < MAX_IDLE:
            if s_cmd is None and k >= k_hold:
                job = engine._active
                s_cmd = job.plan.s_at(k - 1, dt)
                t0 = time.perf_counter()
                engine.command(Command("hold"))
                block = time.perf_counter() - t0
            t0 = time.perf_counter()
            batch = engine.next_batch()
            spent = time.perf_counter() - t0
            if s_cmd is not None and k <= k_hold + round(AFTER_S / dt):
                block = max(block, spent)
                if s_rest is None:
                    s_rest, rest_k = engine._active.plan.s_end, engine._active.plan.k_end
            if batch is None:
                idle += 1
                if not engine.busy:
                    break
                continue
            idle = 0
            checker.feed(batch.pos)
            k = batch.k0 + batch.n
            if batch.final or (rest_k is not None and k > rest_k + 10):
                break
    return {"block_ms": 1e3 * block, "stop_mm": None if s_rest is None else s_rest - s_cmd,
            "violations": checker.report().violations, "method": engine._active.plan.method
            if engine._active is not None else None, "fallbacks": engine.fallbacks}


def _motion_samples(p) -> int:
    """Samples of the path's motion in a fast-mode LP engine (to place the holds)."""
    engine = Engine(p.config, make_planner("lp"))
    for seg in p.segments:
        engine.submit(seg)
    for _ in range(MAX_IDLE):
        batch = engine.next_batch()
        if batch is not None and batch.final:
            return batch.k0 + batch.n
    raise RuntimeError(f"{p.name}: the job did not finish")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--paths", default=",".join(DEFAULT_PATHS))
    ap.add_argument("--holds", type=int, default=6)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args()
    globs = args.paths.split(",")
    out: dict = {"meta": {"holds": args.holds, "seed": args.seed, "after_s": AFTER_S},
                 "paths": {}}
    for p in load_corpus("fast", skip_long=True):
        if not any(fnmatch.fnmatch(p.name, g) for g in globs):
            continue
        n = _motion_samples(p)
        rng = np.random.default_rng(args.seed)
        at = sorted(int(x) for x in rng.integers(n // 20, int(0.8 * n), args.holds))
        at = [k - k % p.config.service.batch for k in at]
        row = out["paths"][p.name] = {"at": at}
        for variant, retime in (("search", False), ("retimed", True)):
            row[variant] = [hold_once(p, retime, k) for k in at]
        for i, k in enumerate(at):
            s, r = row["search"][i], row["retimed"][i]
            print(f"{p.name:36s} k={k:6d} search {s['block_ms']:8.1f} ms {s['stop_mm']!s:.8} "
                  f"mm | retimed {r['block_ms']:6.1f} ms {r['stop_mm']!s:.8} mm "
                  f"({r['method']}) viol {s['violations']}/{r['violations']}",
                  file=sys.stderr, flush=True)
    FsPath(args.out).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
