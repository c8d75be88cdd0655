"""How far the LP's winding time is from the fine-grid reference, per LPPlanner setting.

For each parameter combination (`COMBOS`, or --combo NAME=JSON) and each corpus path:
the whole-job LP (`corpus_bench.run_whole`) and the windowed engine in fast mode
(`corpus_bench.run_engine`), both judged by the finite-difference checker, with the
combination's LPPlanner swapped in for the default one. Per combination: failures
(error, violation, fallback, failed replan), worst and median winding time / reference
(bench/results/corpus_reference.json, corpus_heuristic_ref.json: the fine-grid LP of
bench/reference.py), engine / whole-job time, and compute / the default's compute on the
same path in the same run (median and worst). Results: bench/results/lp_quality.json.

    nice -n 10 .venv/bin/python bench/lp_quality.py --only dome,hel-R50,corners,tube1450 \\
        --combos default,passes2,tl-p2-env0.85 --modes lp,engine

"grid" in a combination is not an LPPlanner argument: it scales `default_grid_step`;
"highs" sets `HighsBackend` class attributes (CARRY, PRIMAL_TOLERANCE, SCALE_STRATEGY) for
the combination.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from pathlib import Path as FsPath
from typing import Any

ROOT = FsPath(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bench import corpus_bench  # noqa: E402

RESULTS = ROOT / "bench" / "results"
REFERENCE_FILES = ("corpus_reference.json", "corpus_heuristic_ref.json")

#: the combinations measured (LPPlanner keyword arguments; "grid": factor on the step)
COMBOS: dict[str, dict[str, Any]] = {
    "default": {},
    "distance": {"objective": "distance"},  # the default before stop 41
    "passes2": {"max_passes": 2},
    "passes3": {"max_passes": 3},
    "time": {"objective": "time"},
    "sqrt": {"objective": "sqrt"},
    "time-p2": {"objective": "time", "max_passes": 2},
    "sqrt-p2": {"objective": "sqrt", "max_passes": 2},
    "time-p3": {"objective": "time", "max_passes": 3},
    "sqrt-p3": {"objective": "sqrt", "max_passes": 3},
    "p2-js0.3": {"max_passes": 2, "jerk_step": 0.3},
    "p2-grid0.5": {"max_passes": 2, "grid": 0.5},
    "p2-grid0.5-js0.3": {"max_passes": 2, "grid": 0.5, "jerk_step": 0.3},
    "p2-env0.85": {"max_passes": 2, "envelope_jerk": 0.85},
    "p2-jm0.92": {"max_passes": 2, "margins": [0.995, 0.98, 0.92]},
    "tp2-env0.85": {"objective": "time", "max_passes": 2, "envelope_jerk": 0.85},
    "tl-p2": {"objective": "time-late", "max_passes": 2},
    #: the recommendation of the 2026-12-02 run (0 failures on 14 + 41 corpus paths)
    "tl-p2-env0.85": {"objective": "time-late", "max_passes": 2, "envelope_jerk": 0.85},
    #: HighsBackend class settings ("highs" is not an LPPlanner argument, see lp_setting)
    #: (results files store each combination's dict, not the defaults it ran against:
    #: lp_quality_carry_* and lp_quality_tol_* ran at the tolerance 1e-7 by default)
    "no-carry": {"highs": {"CARRY": False}},  # each window's first LP cold
    "tol7": {"highs": {"PRIMAL_TOLERANCE": None}},  # HiGHS's default primal tolerance
    "stop41-highs": {"highs": {"CARRY": False, "PRIMAL_TOLERANCE": None}},
    "scale0": {"highs": {"SCALE_STRATEGY": 0}},
    "scale4": {"highs": {"SCALE_STRATEGY": 4}},
}


def reference_times() -> dict[str, float]:
    """Reference winding time per path name (s), from the stored reference runs."""
    out: dict[str, float] = {}
    for name in REFERENCE_FILES:
        f = RESULTS / name
        if not f.exists():
            continue
        for path, entry in json.loads(f.read_text())["paths"].items():
            ref = entry.get("methods", {}).get("reference", {})
            if ref.get("winding_s") and not ref.get("violations"):
                out.setdefault(path, float(ref["winding_s"]))
    return out


@contextlib.contextmanager
def lp_setting(combo: dict[str, Any]):
    """While active, `LPPlanner(...)` as imported by corpus_bench builds the combination's
    planner, `default_grid_step` is scaled by combo["grid"] and `HighsBackend`'s class
    attributes are combo["highs"]."""
    import lookahead.planning.lp as lp_pkg
    from lookahead.planning.lp import planner as planner_mod
    from lookahead.planning.lp.solve import HighsBackend

    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in combo.items()
              if k not in ("grid", "highs")}
    base_cls, base_step = planner_mod.LPPlanner, planner_mod.default_grid_step
    scale = float(combo.get("grid", 1.0))
    backend = combo.get("highs", {})
    saved = {k: getattr(HighsBackend, k) for k in backend}

    def factory(**kw):
        return base_cls(**{**kw, **kwargs})

    def step(path, limits, interval_s: float = 0.0045) -> float:
        return scale * base_step(path, limits, interval_s)

    lp_pkg.LPPlanner = factory  # the package's lazy export is looked up first
    planner_mod.default_grid_step = step
    for k, v in backend.items():
        setattr(HighsBackend, k, v)
    try:
        yield
    finally:
        del lp_pkg.LPPlanner
        planner_mod.default_grid_step = base_step
        for k, v in saved.items():
            setattr(HighsBackend, k, v)


def run_one(p, mode: str, combo: dict[str, Any], timeout: float) -> dict:
    """One (path, mode) under a combination; never raises (errors come back as rows)."""
    def task() -> dict:
        with lp_setting(combo):
            return (corpus_bench.run_engine(p, "engine-lp") if mode == "engine"
                    else corpus_bench.run_whole(p, "lp"))

    out = corpus_bench.run_guarded(task, timeout)
    out.pop("warning_messages", None)
    return out


def _worst_median(vals: list[float]) -> tuple[float | None, float | None]:
    vals = [v for v in vals if v is not None and math.isfinite(v)]
    return (max(vals), float(np.median(vals))) if vals else (None, None)


def summarize(data: dict) -> dict:
    """Per combination and mode: failures, ratios to the reference, compute ratios."""
    refs = data["reference_s"]
    out: dict[str, dict] = {}
    base = data["runs"].get("default", {})
    for name, runs in data["runs"].items():
        out[name] = {}
        for mode in ("lp", "engine"):
            rows = {p: r[mode] for p, r in runs.items() if mode in r}
            if not rows:
                continue
            fails = sorted(p for p, r in rows.items() if corpus_bench.failed(r))
            ratio = {p: r["winding_s"] / refs[p] for p, r in rows.items()
                     if p in refs and corpus_bench.usable(r)}
            comp = {p: r["compute_s"] / base[p][mode]["compute_s"] for p, r in rows.items()
                    if r.get("compute_s") and base.get(p, {}).get(mode, {}).get("compute_s")}
            w, m = _worst_median(list(ratio.values()))
            cw, cm = _worst_median(list(comp.values()))
            row = {"paths": len(rows), "failures": fails, "worst_ref": w, "median_ref": m,
                   "worst_ref_path": max(ratio, key=ratio.get) if ratio else None,
                   "compute_worst": cw, "compute_median": cm,
                   "compute_s": float(sum(r.get("compute_s", 0.0) for r in rows.values()))}
            if mode == "engine":
                whole = {p: r["winding_s"] / runs[p]["lp"]["winding_s"] for p, r in rows.items()
                         if corpus_bench.usable(r) and corpus_bench.usable(runs[p].get("lp"))}
                row["worst_vs_whole"], row["median_vs_whole"] = _worst_median(
                    list(whole.values()))
            out[name][mode] = row
    return out


def table(summ: dict) -> str:
    def f(x, fmt="{:.3f}"):
        return "-" if x is None else fmt.format(x)

    lines = ["| combination | mode | paths | failed | worst / ref (path) | median / ref "
             "| engine / whole worst | compute / default median, worst |",
             "|---|---|---|---|---|---|---|---|"]
    for name, modes in summ.items():
        for mode, r in modes.items():
            lines.append(
                f"| {name} | {mode} | {r['paths']} | {len(r['failures'])} "
                f"{' '.join(r['failures'])} | {f(r['worst_ref'])} ({r['worst_ref_path']}) | "
                f"{f(r['median_ref'])} | {f(r.get('worst_vs_whole'))} | "
                f"{f(r['compute_median'], '{:.2f}')}, {f(r['compute_worst'], '{:.2f}')} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subset", default="fast", help='load_corpus subset ("fast" or "all")')
    ap.add_argument("--only", default="", help="comma-separated name substrings")
    ap.add_argument("--skip", default="", help="comma-separated name substrings to leave out")
    ap.add_argument("--combos", default="default,passes2,tl-p2-env0.85",
                    help="names in COMBOS")
    ap.add_argument("--combo", action="append", default=[], help="NAME=JSON kwargs")
    ap.add_argument("--modes", default="lp,engine")
    ap.add_argument("--timeout", type=float, default=120.0, help="per task (s)")
    ap.add_argument("--out", default=str(RESULTS / "lp_quality.json"))
    ap.add_argument("--fresh", action="store_true", help="do not merge into --out")
    args = ap.parse_args(argv)

    import logging

    logging.getLogger("lookahead").setLevel(logging.WARNING)
    logging.getLogger("lookahead").propagate = False
    from bench.corpus import load_corpus

    combos = {n: COMBOS[n] for n in args.combos.split(",") if n}
    for spec in args.combo:
        name, _, kw = spec.partition("=")
        combos[name] = json.loads(kw)
    if "default" not in combos:
        combos = {"default": {}, **combos}  # the compute ratios need it in the same run
    only = [s for s in args.only.split(",") if s]
    skip = [s for s in args.skip.split(",") if s]
    paths = [p for p in load_corpus(args.subset, skip_long=True)
             if (not only or any(s in p.name for s in only))
             and not any(s in p.name for s in skip)]
    out = FsPath(args.out)
    data = (json.loads(out.read_text()) if out.exists() and not args.fresh
            else {"runs": {}, "combos": {}})
    data["reference_s"] = reference_times()
    data["git"] = corpus_bench.git_state()
    modes = [m for m in args.modes.split(",") if m]
    for p in paths:  # path-major: every combination sees the same machine load
        for name, combo in combos.items():
            data["combos"][name] = combo
            row = data["runs"].setdefault(name, {}).setdefault(p.name, {})
            for mode in modes:
                row[mode] = run_one(p, mode, combo, args.timeout)
                r = row[mode]
                ref = data["reference_s"].get(p.name)
                corpus_bench.log(
                    f"{p.name:40s} {name:18s} {mode:6s} "
                    f"T={r.get('winding_s', float('nan')):8.3f} "
                    f"ref={'%.3f' % (r['winding_s'] / ref) if ref and 'winding_s' in r else '-':6s}"
                    f" c={r.get('compute_s', r['task_s']):6.2f}s "
                    f"fb={r.get('fallbacks', 0)} v={r.get('violations', 0)} "
                    f"{r.get('error', '')[:120]}")
            data["summary"] = summarize(data)
            out.write_text(json.dumps(data, indent=1, default=float))
    print(table(data["summary"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
