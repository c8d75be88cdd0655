"""The windowed LP as the service runs it, on the path corpus (issue 13 items 2 and 4).

Every corpus path's segments go into a `lookahead.stream.engine.Engine` planning with the
LP (HiGHS and/or OSQP), in fast mode, the way `clients/lookahead_clients/replay.py` drives
it; the whole setpoint stream is judged by the finite-difference checker. Per path and
solver: fallbacks (windows the LP could not make; the heuristic made them), replan failures
(neither could; the plan in force stayed), checker violations, motion time, compute time
(wall clock of the engine, planning and sampling) and x real time. Worst first.

    .venv/bin/python bench/lp_engine_bench.py [--subset fast|all] [--solver highs osqp]
        [--pattern GLOB] [--skip-long] [--ab]

--solver takes the `lp.solve` backends: highs (persistent warm-started highspy model),
highs-milp (cold `scipy.optimize.milp` per solve: the A/B partner of highs), osqp.

--ab: each path twice in turn in one process, "before" (the round-2 fixes of issue 13
switched off: no secant accelerations at reversing intervals, no early end of hopeless
repair loops, no rest nodes at near-reversals) then "after", so the two compute times
share the machine's load.

Results: bench/results/lp_engine.json (one row per path and solver).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path as FilePath

import numpy as np

ROOT = FilePath(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.corpus import load_corpus  # noqa: E402
from lookahead.checker import LimitChecker  # noqa: E402
from lookahead.planning.lp import LPPlanner  # noqa: E402
from lookahead.planning.lp import planner as lp_planner  # noqa: E402
from lookahead.planning.lp import profile as lp_profile  # noqa: E402
from lookahead.stream.engine import Engine  # noqa: E402

RESULTS = ROOT / "bench" / "results" / "lp_engine.json"
WHAT = ("corpus paths through lookahead.stream.engine.Engine (fast mode) with the LP; "
        "fallbacks = windows the LP could not make (the heuristic made them); violations "
        "from the finite-difference checker over the whole stream; compute_s = engine wall "
        "clock on a loaded 2-core machine (x_realtime = motion_s / compute_s, a lower "
        "bound); variant: see --ab. bench/lp_engine_bench.py")
#: engine calls without a batch before a job counts as stuck
MAX_IDLE = 200_000


#: the round-2 switches of --ab and their "after" values
AB_SWITCHES = ((lp_profile, "REVERSAL_ROUNDS", lp_profile.REVERSAL_ROUNDS, 0),
               (lp_planner, "HOPELESS_RATIO", lp_planner.HOPELESS_RATIO, float("inf")),
               (lp_planner, "near_reversals", lp_planner.near_reversals,
                lambda path, h: np.empty(0)))


def set_variant(after: bool) -> None:
    """Switch the round-2 fixes on (after) or off (before) for --ab."""
    for module, name, on, off in AB_SWITCHES:
        setattr(module, name, on if after else off)


def run_job(path, solver: str) -> dict:
    """One corpus path through the engine with the LP on `solver`."""
    cfg = path.config
    engine = Engine(cfg, LPPlanner(solver=solver))
    checker = LimitChecker(cfg.machine.limits, cfg.machine.dt)
    t0 = time.perf_counter()
    for seg in path.segments:
        engine.submit(seg)
    samples, idle, finished = 0, 0, False
    while idle < MAX_IDLE:
        batch = engine.next_batch()
        if batch is None:
            idle += 1
            if not engine.busy:
                break
            continue
        idle = 0
        checker.feed(batch.pos)
        samples += batch.n
        if batch.final:
            finished = True
            break
    wall = time.perf_counter() - t0
    rep = checker.report()
    motion = max(samples - 1, 0) * cfg.machine.dt
    return {"path": path.name, "family": path.family, "solver": solver,
            "finished": finished, "fallbacks": engine.fallbacks,
            "replan_failures": engine.replan_failures, "replans": engine.replans,
            "violations": rep.violations, "motion_s": motion, "compute_s": wall,
            "x_realtime": motion / wall if wall > 0 else float("inf")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--subset", default="fast", choices=("fast", "all"))
    ap.add_argument("--solver", nargs="+", default=["highs", "osqp"])
    ap.add_argument("--pattern", default=None)
    ap.add_argument("--skip-long", action="store_true")
    ap.add_argument("--ab", action="store_true")
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    rows = []
    for path in load_corpus(args.subset, args.pattern, args.skip_long):
        for solver in args.solver:
            for variant in (("before", "after") if args.ab else ("current",)):
                set_variant(variant != "before")
                try:
                    row = run_job(path, solver)
                except Exception as exc:  # a crash is a result too
                    row = {"path": path.name, "family": path.family, "solver": solver,
                           "finished": False, "error": f"{type(exc).__name__}: {exc}"}
                row["variant"] = variant
                rows.append(row)
                print(json.dumps(row), flush=True)
    set_variant(True)
    bad = sorted(rows, key=lambda r: (r.get("finished", False), -r.get("fallbacks", 0),
                                      r.get("x_realtime", 0.0)))
    print("\nworst first: path solver variant fallbacks failures violations motion_s "
          "x_realtime")
    for r in bad:
        print(f"{r['path']:<40} {r['solver']:<6} {r['variant']:<7} {r.get('fallbacks', '-'):>4} "
              f"{r.get('replan_failures', '-'):>4} {r.get('violations', '-'):>4} "
              f"{r.get('motion_s', float('nan')):8.2f} {r.get('x_realtime', float('nan')):8.1f}")
    FilePath(args.out).parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", encoding="utf-8") as fh:
        json.dump({"what": WHAT, "subset": args.subset, "solvers": args.solver, "ab": args.ab,
                   "rows": rows}, fh, indent=1,
                  default=lambda x: float(x) if isinstance(x, np.floating) else str(x))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
