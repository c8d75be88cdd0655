"""Where the streaming engine's time goes (issues 13/14: x real time through the engine).

Runs `lookahead.stream.engine.Engine` in fast mode exactly as `bench/corpus_bench.py`'s
`engine-*` methods do (Engine built, every segment submitted, batches drawn until the final
one, each batch fed to the bench's own checker; wall time from the Engine's construction),
and splits the wall time into buckets by wrapping a few functions with perf_counter timers:

- `submit`: `Engine.submit` (segment order, fits, of which `excursions`: the fit
  excursion warnings of `JobGeometry._check_excursions`),
- `planner`: the planner's `plan` calls (what corpus_bench's replan p50/p99 measure),
- `sample`: the committed plan's samples (`CommittedPlan.with_samples`),
- `verify`: the finite-difference check of each plan (`lookahead.stream.plans.verify`),
- `state`: path states of the plan in force (`CommittedPlan.state`),
- `batch`: building batches (`Engine._produce` minus `Engine._maybe_replan`),
- `replan_other`: the rest of `_maybe_replan` (requests, feed caps, bookkeeping),
- `bench_check`: the bench's own checker (counted in corpus_bench's wall time too),
- `other`: the remainder of the wall time.
Timers cost ~1 us a call (a few thousand calls per job), negligible here.

A/B (`--ab DIR`): each (path, method) also runs with `DIR` (a copy of the `service/`
folder of another tree, e.g. `git archive HEAD | tar -x -C /tmp/base` then
`--ab /tmp/base/service`) first on PYTHONPATH, in a fresh subprocess, alternating with the
current tree (or `--tree DIR`, another such folder), `--repeat` times each; the minimum
wall time of each is reported, and whether both trees produced bit-identical setpoints (a
hash of every batch's pos/vel/acc).

Results: `--out` (default bench/results/engine_profile.json); a table on stdout, worst x
real time first. `--cprofile N` prints the N functions with the most internal time instead
(one path, one method, current tree). Run from the repository root:

    .venv/bin/python bench/engine_profile.py
    .venv/bin/python bench/engine_profile.py --ab /tmp/base/service --repeat 3
    .venv/bin/python bench/engine_profile.py --only c-rand6* --methods engine-heuristic \
        --cprofile 40
"""

from __future__ import annotations

import argparse
import fnmatch
import hashlib
import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path as FsPath
from typing import Any

ROOT = FsPath(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "bench" / "results"
#: the paths of the brief: the tube, a real CAM hoop, 6 axes of very different scales and a
#: 3000-point Fourier path (all in the fast corpus)
DEFAULT_PATHS = ("w-issue-tube1450-R100-a45-sine-2mm", "cam-fp-hoop-D60-L80-noB",
                 "c-rand6-scales-1e-2-1e4-norm", "c-fourier-xc-3000pts")
METHODS = ("engine-heuristic", "engine-lp")
BUCKETS = ("submit", "excursions", "planner", "sample", "verify", "state", "batch",
           "replan_other", "bench_check", "other")


class _Timers:
    """Inclusive wall time and call count per bucket."""

    def __init__(self) -> None:
        self.total: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self.planner_ms: list[float] = []

    def add(self, key: str, dt: float) -> None:
        self.total[key] = self.total.get(key, 0.0) + dt
        self.calls[key] = self.calls.get(key, 0) + 1


def _wrap(owner: Any, name: str, key: str, timers: _Timers) -> None:
    """Replace owner.name by a timed forwarder (no-op if owner has no such attribute)."""
    inner = owner.__dict__.get(name) if isinstance(owner, type) else getattr(owner, name, None)
    if inner is None:
        return
    if isinstance(inner, (staticmethod, classmethod)):
        return

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            timers.add(key, time.perf_counter() - t0)

    timed.__wrapped__ = inner  # type: ignore[attr-defined]
    setattr(owner, name, timed)


def _install(timers: _Timers) -> None:
    from lookahead.stream import assembler, engine, plans

    _wrap(engine.Engine, "submit", "submit", timers)
    _wrap(engine.Engine, "_produce", "produce", timers)
    _wrap(engine.Engine, "_maybe_replan", "replan", timers)
    _wrap(assembler.JobGeometry, "_check_excursions", "excursions", timers)
    _wrap(plans.CommittedPlan, "with_samples", "sample", timers)
    _wrap(plans.CommittedPlan, "state", "state", timers)
    _wrap(plans, "verify", "verify", timers)


class _TimedPlanner:
    def __init__(self, inner, timers: _Timers) -> None:
        self.inner = inner
        self.name = inner.name
        self.timers = timers

    def plan(self, request, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return self.inner.plan(request, *args, **kwargs)
        finally:
            dt = time.perf_counter() - t0
            self.timers.add("planner", dt)
            self.timers.planner_ms.append(dt * 1e3)

    def __getattr__(self, item: str):
        return getattr(self.inner, item)


def _make_planner(method: str):
    if method == "engine-heuristic":
        from lookahead.planning.heuristic import HeuristicPlanner

        return HeuristicPlanner(margin=1.0)
    from lookahead.planning.lp import LPPlanner

    return LPPlanner(solver="osqp" if method == "engine-osqp" else "highs")


def _pct(values: list[float], q: float) -> float | None:
    if not values:
        return None
    import numpy as np

    return float(np.percentile(values, q))


def run_one(name: str, method: str, timed: bool = True) -> dict:
    """One (path, method) in this process: wall time, buckets, replans, setpoint hash."""
    import numpy as np

    from bench.corpus_bench import _corpus_path, engine_batches
    from lookahead.checker import LimitChecker
    from lookahead.stream.engine import Engine

    logging.getLogger("lookahead").setLevel(logging.WARNING)
    p = _corpus_path(name)
    segments = p.segments
    timers = _Timers()
    if timed:
        _install(timers)
    planner = _TimedPlanner(_make_planner(method), timers)
    m = p.config.machine
    digest = hashlib.blake2b(digest_size=16)
    t0 = time.perf_counter()
    engine = Engine(p.config, planner, realtime=False)
    for seg in segments:
        engine.submit(seg)
    checker = LimitChecker(m.limits, m.dt)
    samples, final, check_s = 0, False, 0.0
    batches = []
    for batch in engine_batches(engine):
        tc = time.perf_counter()
        checker.feed(batch.pos)
        check_s += time.perf_counter() - tc
        batches.append(batch)
        samples += batch.n
        final = batch.final
    wall = time.perf_counter() - t0
    for b in batches:
        for arr in (b.pos, b.vel, b.acc):
            digest.update(np.ascontiguousarray(arr, dtype="<f8").tobytes())
    rep = checker.report()
    winding = max(samples - 1, 0) * m.dt
    tot = timers.total
    buckets = {
        "submit": tot.get("submit", 0.0) - tot.get("excursions", 0.0),
        "excursions": tot.get("excursions", 0.0),
        "planner": tot.get("planner", 0.0),
        "sample": tot.get("sample", 0.0),
        "verify": tot.get("verify", 0.0),
        "state": tot.get("state", 0.0),
        "batch": tot.get("produce", 0.0) - tot.get("replan", 0.0),
        "bench_check": check_s,
    }
    buckets["replan_other"] = tot.get("replan", 0.0) - sum(
        buckets[k] for k in ("planner", "sample", "verify", "state"))
    buckets["other"] = wall - sum(buckets.values())
    return {
        "path": name, "method": method, "winding_s": winding, "wall_s": wall,
        "x_realtime": winding / wall if wall > 0 else None, "final": final,
        "replans": engine.replans, "fallbacks": engine.fallbacks,
        "replan_failures": engine.replan_failures, "plans": len(timers.planner_ms),
        "plan_ms_p50": _pct(timers.planner_ms, 50), "plan_ms_p99": _pct(timers.planner_ms, 99),
        "violations": rep.violations, "setpoint_hash": digest.hexdigest(),
        "buckets_s": buckets if timed else None,
        "calls": dict(timers.calls) if timed else None,
    }


def _subprocess(name: str, method: str, service_dir: str | None) -> dict:
    env = dict(os.environ)
    if service_dir:
        env["PYTHONPATH"] = service_dir + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, str(FsPath(__file__).resolve()), "--child", name, method]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        return {"path": name, "method": method, "error": out.stderr[-2000:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def _best(runs: list[dict]) -> dict:
    ok = [r for r in runs if "error" not in r]
    if not ok:
        return runs[0]
    best = dict(min(ok, key=lambda r: r["wall_s"]))
    best["wall_s_runs"] = [r["wall_s"] for r in ok]
    best["hashes_agree"] = len({r["setpoint_hash"] for r in ok}) == 1
    return best


def _paths(args) -> list[str]:
    if args.subset:
        from bench.corpus import load_corpus

        names = [p.name for p in load_corpus(args.subset)]
    else:
        names = list(DEFAULT_PATHS)
    if args.only:
        names = [n for n in names if any(fnmatch.fnmatchcase(n, g) for g in args.only)]
    return names


def _fmt_row(r: dict, base: dict | None) -> str:
    b = r.get("buckets_s") or {}
    parts = " ".join(f"{k}={1e3 * b.get(k, 0.0):.0f}" for k in BUCKETS if b.get(k, 0) > 5e-4)
    x = r.get("x_realtime") or 0.0
    head = f"{r['path'][:38]:38s} {r['method']:17s} {x:7.1f}x"
    if base is not None and "error" not in base:
        same = "same" if base["setpoint_hash"] == r["setpoint_hash"] else "DIFFERENT"
        head += f" (was {base['x_realtime']:6.1f}x, {same} setpoints, winding " \
                f"{r['winding_s']:.3f} vs {base['winding_s']:.3f} s)"
    return (f"{head} wall {r['wall_s'] * 1e3:.0f} ms, {r['replans']} replans, plan p50/p99 "
            f"{r['plan_ms_p50'] or 0:.1f}/{r['plan_ms_p99'] or 0:.1f} ms; ms: {parts}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subset", choices=("fast", "all"), default=None,
                    help="corpus subset (default: the four paths of DEFAULT_PATHS)")
    ap.add_argument("--only", nargs="*", default=None, help="glob(s) on path names")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--repeat", type=int, default=1, help="runs per (tree, path, method)")
    ap.add_argument("--ab", default=None, help="a service/ folder to compare against")
    ap.add_argument("--tree", default=None,
                    help="a service/ folder to run instead of this tree's (A/B of snapshots)")
    ap.add_argument("--out", default=str(RESULTS / "engine_profile.json"))
    ap.add_argument("--cprofile", type=int, default=0, help="print the top N functions")
    ap.add_argument("--child", nargs=2, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(run_one(*args.child)))
        return 0
    methods = [m for m in args.methods.split(",") if m]
    names = _paths(args)
    if args.cprofile:
        import cProfile
        import pstats

        run_one(names[0], methods[0], timed=False)  # imports and corpus generation
        prof = cProfile.Profile()
        prof.enable()
        r = run_one(names[0], methods[0], timed=False)
        prof.disable()
        print(_fmt_row(r, None))
        pstats.Stats(prof).sort_stats("tottime").print_stats(args.cprofile)
        return 0
    rows = []
    for name in names:
        for method in methods:
            new_runs, base_runs = [], []
            for _ in range(max(args.repeat, 1)):
                if args.ab:
                    base_runs.append(_subprocess(name, method, args.ab))
                new_runs.append(_subprocess(name, method, args.tree))
            new = _best(new_runs)
            base = _best(base_runs) if args.ab else None
            rows.append({"new": new, "base": base})
            print(_fmt_row(new, base) if "error" not in new else f"{name} {method}: "
                  f"{new['error']}", file=sys.stderr, flush=True)
    rows.sort(key=lambda t: t["new"].get("x_realtime") or 0.0)
    print("\nworst x real time first:")
    for t in rows:
        if "error" not in t["new"]:
            print(_fmt_row(t["new"], t["base"]))
    out = {"meta": {"time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                    "ab": args.ab, "tree": args.tree, "repeat": args.repeat, "methods": methods,
                    "buckets": list(BUCKETS)},
           "rows": rows}
    FsPath(args.out).parent.mkdir(parents=True, exist_ok=True)
    FsPath(args.out).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
