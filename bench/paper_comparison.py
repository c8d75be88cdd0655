"""The paper's comparison (its Figs. 7-11): heuristic, LP (whole job), LP (windowed; HiGHS,
and OSQP beside it) and NLP on the winding presets, beside the TOPPRA
velocity+acceleration bound.

For each preset (`tube-1450`, `tube-9570`: one circuit, fitted with a C2 cubic, machine
limits of `default_config()`): winding time (s), computation time (median of several runs;
the NLP fewer), real-time factor (winding time / compute time), ratio of the winding time
to the bound, and from the finite-difference checker the violations (must be 0) and the
peak |v|, |a|, |j| per axis as fractions of the limits.

Writes bench/results/paper_comparison.json and .png. Run from the repository root:
    /tmp/venv/bin/python bench/paper_comparison.py [--quick] [--presets tube-1450 ...]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path as FsPath

import numpy as np

from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry import fit_points, preset_points
from lookahead.planning.base import PathState, PlanRequest, PlanResult
from lookahead.planning.bounds import toppra_time_bound
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.planning.lp import LPPlanner
from lookahead.planning.lp.window import WindowedLP
from lookahead.planning.nlp import NLPPlanner
from lookahead.sampling import sample_plan

RESULTS = FsPath(__file__).resolve().parent / "results"
METHODS = ("heuristic", "lp", "lp-windowed", "lp-windowed-osqp", "nlp")
#: methods left out of the feed plot (on top of another line there)
NOT_PLOTTED = ("lp-windowed-osqp",)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def make_planner(method: str):
    if method == "lp-windowed-osqp":
        return WindowedLP(planner=LPPlanner(solver="osqp"))
    return {"heuristic": HeuristicPlanner, "lp": LPPlanner, "lp-windowed": WindowedLP,
            "nlp": NLPPlanner}[method]()


def run_method(method: str, request: PlanRequest, repeats: int) -> tuple[PlanResult, list[float]]:
    """Plan `repeats` times with fresh planners; the last result and all wall times (s)."""
    times, result = [], None
    for _ in range(repeats):
        planner = make_planner(method)
        t0 = time.perf_counter()
        result = planner.plan(request)
        times.append(time.perf_counter() - t0)
    return result, times


def measure(preset: str, repeats: dict[str, int]) -> dict:
    cfg = default_config().machine
    _, points, info = preset_points(preset)
    path = fit_points(points, np.asarray(cfg.path_scale), "cubic")
    limits, dt = cfg.limits, cfg.dt
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=dt)
    log(f"[{preset}] path {path.length:.0f} mm; toppra bound ...")
    t0 = time.perf_counter()
    bound = toppra_time_bound(path, limits, gridpoints=4000)
    out = {"preset": preset, "description": info.description, "length_mm": path.length,
           "points": int(points.shape[0]), "toppra_bound_s": bound,
           "toppra_compute_s": time.perf_counter() - t0, "methods": {}, "profiles": {}}
    for method in METHODS:
        log(f"[{preset}] {method}: {repeats[method]} run(s) ...")
        result, times = run_method(method, request, repeats[method])
        rep = check_positions(sample_plan(path, result.profile, dt).pos, limits, dt)
        T, c = result.profile.duration, statistics.median(times)
        row = {"winding_time_s": T, "compute_s_median": c, "compute_s_runs": times,
               "runs": len(times), "realtime_factor": T / c, "ratio_to_bound": T / bound,
               "violations": rep.violations, "peak_fraction": rep.peak_fraction}
        if method == "nlp":
            row["nlp_windows"] = result.info["windows"]
            row["nlp_fallback"] = result.info["fallback"]
            row["nlp_start_time_s"] = result.info["start_time_s"]
        out["methods"][method] = row
        t = np.linspace(0.0, T, 4000)
        s, v, _, _ = result.profile.at(t)
        out["profiles"][method] = {"s": s[::4].tolist(), "v": v[::4].tolist()}
        log(f"[{preset}] {method}: {T:.3f} s motion, {c:.3f} s compute, "
            f"{rep.violations} violations")
    return out


def table(results: list[dict]) -> str:
    lines = ["| preset | method | winding s | / bound | compute s (runs) | x real time "
             "| violations | peak v X,C | peak a X,C | peak j X,C |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        lines.append(f"| {r['preset']} | toppra bound (v+a) | {r['toppra_bound_s']:.3f} | 1 "
                     f"| {r['toppra_compute_s']:.2f} | | | | | |")
        for m, row in r["methods"].items():
            pf = row["peak_fraction"]
            fmt = ",".join
            lines.append(
                f"| {r['preset']} | {m} | {row['winding_time_s']:.3f} "
                f"| {row['ratio_to_bound']:.4f} | {row['compute_s_median']:.2f} ({row['runs']}) "
                f"| {row['realtime_factor']:.1f} | {row['violations']} "
                f"| {fmt(f'{x:.3f}' for x in pf['v'])} | {fmt(f'{x:.3f}' for x in pf['a'])} "
                f"| {fmt(f'{x:.3f}' for x in pf['j'])} |")
    return "\n".join(lines)


def figure(results: list[dict], out_png: FsPath) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(12, 8))
    grid = fig.add_gridspec(2, 2)
    ax = fig.add_subplot(grid[0, :])
    first = results[0]
    for m, prof in first["profiles"].items():
        if m in NOT_PLOTTED:
            continue
        ax.plot(prof["s"], prof["v"], label=m, lw=1)
    ax.set_xlabel("s (mm)")
    ax.set_ylabel("feed (mm/s)")
    ax.set_title(f"{first['preset']}: feed along the path")
    ax.legend()
    x = np.arange(len(METHODS))
    width = 0.8 / len(results)
    for k, (key, label) in enumerate((("compute_s_median", "computation time (s)"),
                                      ("winding_time_s", "winding time (s)"))):
        axb = fig.add_subplot(grid[1, k])
        for i, r in enumerate(results):
            vals = [r["methods"][m][key] for m in METHODS]
            axb.bar(x + i * width, vals, width, label=r["preset"])
            if key == "winding_time_s":
                axb.axhline(r["toppra_bound_s"], ls=":", color=f"C{i}", lw=1)
        axb.set_xticks(x + 0.4 - width / 2, METHODS, rotation=15)
        axb.set_ylabel(label)
        if key == "compute_s_median":
            axb.set_yscale("log")
        axb.legend()
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="one run per method (smoke test)")
    ap.add_argument("--presets", nargs="+", default=["tube-1450", "tube-9570"])
    ap.add_argument("--out", default=str(RESULTS), help="output directory")
    args = ap.parse_args(argv)
    if args.quick:
        repeats = dict.fromkeys(METHODS, 1)
    else:
        repeats = {"heuristic": 5, "lp": 5, "lp-windowed": 5, "lp-windowed-osqp": 3, "nlp": 2}
    out_dir = FsPath(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = [measure(p, repeats) for p in args.presets]
    lim = default_config().machine.limits
    payload = {"quick": args.quick, "repeats": repeats,
               "limits": {k: getattr(lim, k).tolist() for k in ("vmax", "amax", "jmax")},
               "nlp_compute_note": "NLP compute includes its start plan (an LP run)",
               "results": results}
    (out_dir / "paper_comparison.json").write_text(json.dumps(payload, indent=1))
    figure(results, out_dir / "paper_comparison.png")
    print(table(results))
    bad = [(r["preset"], m) for r in results for m, row in r["methods"].items()
           if row["violations"]]
    if bad:
        log(f"VIOLATIONS in {bad}")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
