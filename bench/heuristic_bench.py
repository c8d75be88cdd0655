"""Heuristic planner benchmark (issue 14): winding time, checker violations and compute time
on the heuristic's test paths (tests/heuristic_paths.py), beside the windowed LP, a
fine-grid LP reference and the TOPPRA velocity+acceleration bound.

Per path: each method's motion time (s), its ratio to the bound, finite-difference checker
violations (lookahead.checker on lookahead.sampling output; must be 0), compute time
(median of runs) and real-time factor; for the heuristic also the per-replan compute time
of windowed replans from mid-motion states (median, p99).

Writes bench/results/heuristic.json (or --out). Run from the repository root:
    nice -n 10 .venv/bin/python bench/heuristic_bench.py [--quick] [--no-lp] [--label X]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path as FsPath

import numpy as np

ROOT = FsPath(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from heuristic_paths import Case, cases  # noqa: E402
from lookahead.checker import check_positions  # noqa: E402
from lookahead.planning.base import PathState, PlanningError, PlanRequest  # noqa: E402
from lookahead.planning.bounds import toppra_time_bound  # noqa: E402
from lookahead.sampling import sample_plan  # noqa: E402

RESULTS = ROOT / "bench" / "results"
#: replans per path for the per-replan timing, and their window (braking distances at the
#: path's top feed are ~100-400 mm on the winder; the service plans ~3 of them ahead)
REPLANS = 40
WINDOW_MM = 600.0


def corpus_cases(subset: str) -> list[Case]:
    """The corpus paths as bench cases: the service's fit, the job's machine limits."""
    sys.path.insert(0, str(ROOT))
    from bench.corpus import load_corpus

    out = []
    for p in load_corpus(subset, skip_long=True):
        m = p.config.machine
        out.append(Case(p.name, p.path(), m.limits, m.dt))
    return out


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


#: where the heuristic under test comes from: None for lookahead's own, else a module
#: name on sys.path (`--heuristic-module`, e.g. the previous version extracted with
#: `git show HEAD:...` into a package for a before/after comparison)
HEURISTIC_MODULE: str | None = None


def _heuristic():
    if HEURISTIC_MODULE:
        import importlib

        return importlib.import_module(HEURISTIC_MODULE).HeuristicPlanner(margin=1.0)
    from lookahead.planning.heuristic import HeuristicPlanner

    return HeuristicPlanner(margin=1.0)


def _lp_module():
    try:
        from lookahead.planning.lp import LPPlanner, default_grid_step
    except ImportError:  # the LP package layout
        from lookahead.planning.lp.grid import default_grid_step  # type: ignore[no-redef]
        from lookahead.planning.lp.planner import LPPlanner  # type: ignore[no-redef]
    return LPPlanner, default_grid_step


def _windowed_lp():
    from lookahead.planning.lp.window import WindowedLP

    return WindowedLP()


def _fine_lp(case: Case):
    LPPlanner, default_grid_step = _lp_module()
    return LPPlanner(grid_step=default_grid_step(case.path, case.limits) / 3.0)


def run(case: Case, make, repeats: int) -> dict:
    request = PlanRequest(case.path, case.limits, PathState(0.0), case.path.length,
                          feed_cap=case.feed_cap, dt=case.dt)
    times, result, error = [], None, ""
    for _ in range(repeats):
        planner = make()
        t0 = time.perf_counter()
        try:
            result = planner.plan(request)
        except PlanningError as exc:
            error = str(exc)[:200]
            break
        times.append(time.perf_counter() - t0)
    if result is None or error:
        return {"error": error or "no result"}
    rep = check_positions(sample_plan(case.path, result.profile, case.dt).pos, case.limits,
                          case.dt)
    T, c = result.profile.duration, statistics.median(times)
    return {"time_s": T, "compute_s": c, "realtime": T / c, "violations": rep.violations,
            "peak_j": max(rep.peak_fraction["j"]), "_profile": result.profile}


def replans(case: Case, full) -> dict:
    """Per-replan compute time: windows [s_k, s_k + WINDOW_MM] from states of the full
    plan at random times, checked joined to the full plan's samples before them."""
    rng = np.random.default_rng(11)
    T = full.duration
    planner = _heuristic()
    times, bad, failed = [], 0, 0
    first = sample_plan(case.path, full, case.dt).pos
    for k in np.sort(rng.integers(1, max(int(T / case.dt) - 1, 2), REPLANS)):
        st = full.state_at(k * case.dt)
        s_end = min(st.s + WINDOW_MM, case.path.length)
        if not s_end > st.s:
            continue
        req = PlanRequest(case.path, case.limits, st, s_end, feed_cap=case.feed_cap,
                          dt=case.dt)
        t0 = time.perf_counter()
        try:
            res = planner.plan(req)
        except PlanningError:
            failed += 1
            continue
        times.append(time.perf_counter() - t0)
        tail = sample_plan(case.path, res.profile, case.dt).pos
        rep = check_positions(np.vstack([first[:k], tail]), case.limits, case.dt)
        bad += int(rep.violations > 0)
    arr = np.array(times) if times else np.zeros(1)
    return {"replans": len(times), "failed": failed, "violating": bad,
            "median_ms": 1e3 * float(np.median(arr)),
            "p99_ms": 1e3 * float(np.quantile(arr, 0.99))}


def measure(case: Case, with_lp: bool) -> dict:
    log(f"[{case.name}] length {case.path.length:.0f}")
    out: dict = {"name": case.name, "length": case.path.length}
    try:
        out["bound_s"] = toppra_time_bound(case.path, case.limits, gridpoints=4000)
    except Exception as exc:  # toppra fails on some paths (cusps); the bound is optional
        out["bound_s"] = None
        log(f"  toppra: {exc}")
    methods = {"heuristic": (_heuristic, 5)}
    if with_lp:
        methods["lp-windowed"] = (_windowed_lp, 1)
        methods["lp-fine"] = (lambda: _fine_lp(case), 1)
    for name, (make, repeats) in methods.items():
        row = run(case, make, repeats)
        profile = row.pop("_profile", None)
        if name == "heuristic" and profile is not None:
            row.update(replans(case, profile))
        out[name] = row
        log(f"  {name}: {json.dumps(row)}")
    return out


def summary(results: list[dict]) -> str:
    lines = ["| path | heuristic s | viol | /bound | /lp-win | /lp-fine | x real time "
             "| replan p99 ms |", "|---|---|---|---|---|---|---|---|"]
    for r in results:
        h = r["heuristic"]
        if "error" in h:
            lines.append(f"| {r['name']} | ERROR {h['error'][:60]} | | | | | | |")
            continue

        def ratio(key, h=h, r=r):
            ref = r.get(key)
            ref = ref.get("time_s") if isinstance(ref, dict) else ref
            return f"{h['time_s'] / ref:.3f}" if ref else "-"

        lines.append(f"| {r['name']} | {h['time_s']:.3f} | {h['violations']} "
                     f"| {ratio('bound_s')} | {ratio('lp-windowed')} | {ratio('lp-fine')} "
                     f"| {h['realtime']:.0f} | {h['p99_ms']:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the small paths only")
    ap.add_argument("--no-lp", action="store_true", help="skip the LP references")
    ap.add_argument("--only", nargs="*", help="path names to run")
    ap.add_argument("--label", default="heuristic", help="results file stem")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--corpus", choices=("fast", "all"),
                    help="the corpus paths (bench/corpus, long ones skipped) instead")
    ap.add_argument("--heuristic-module", help="import HeuristicPlanner from this module "
                    "instead (a directory holding it goes first on sys.path: --path-dir)")
    ap.add_argument("--path-dir", help="a directory put first on sys.path")
    args = ap.parse_args(argv)
    global HEURISTIC_MODULE
    if args.path_dir:
        sys.path.insert(0, args.path_dir)
    HEURISTIC_MODULE = args.heuristic_module
    todo = corpus_cases(args.corpus) if args.corpus else cases(args.quick)
    todo = [c for c in todo if not args.only or c.name in args.only]
    results = [measure(c, not args.no_lp) for c in todo]
    out = FsPath(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{args.label}.json").write_text(json.dumps({"results": results}, indent=1))
    print(summary(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
