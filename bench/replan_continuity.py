"""Replans from states on committed plans (issues 13 and 14): a planner that the service
runs must plan from any state its own last plan passes through, since that is where every
replan starts. The engine's own runs reach only the states of its replan cadence; this
bench reaches the others too (braking into a window's end at low feed, mid-acceleration),
where the long CAM program's heuristic replans failed ("no brake within the limits from
v=11.07, a=-187.7").

Per corpus path and planner (`heuristic`, `lp`): plan the first window from rest, as the
engine does (its length `horizon_length` at the planning limits, margin applied); take
`--states` states of that plan at seeded random times plus its last 2 % (the braking into
the window's end); replan from each to one window further; count the replans that raise
PlanningError or that the engine's own check (`stream.plans.plan_checked`) refuses. Results
(failures first, with the state and the reason) to bench/results/replan_continuity.json.

    .venv/bin/python bench/replan_continuity.py [--subset fast|all] [--methods heuristic,lp]
        [--paths GLOB,...] [--states 40] [--mode seamed|cold] [--states-from heuristic]

`--states-from heuristic --methods lp`: the LP replans from states of the heuristic's plan
(what it meets after a fallback, or taking over from another planner).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import time
from pathlib import Path as FsPath

ROOT = FsPath(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bench.corpus import load_corpus  # noqa: E402
from lookahead.planning.base import PathState, PlanningError, PlanRequest  # noqa: E402
from lookahead.stream.engine import horizon_length  # noqa: E402
from lookahead.stream.planners import make_planner  # noqa: E402
from lookahead.stream.plans import S_TOL, CommittedPlan, plan_checked  # noqa: E402

OUT = ROOT / "bench" / "results" / "replan_continuity.json"
#: fraction of the first plan's duration at its end sampled densely (its braking to rest)
END_SHARE = 0.02


def states_on(profile, n: int, rng: np.random.Generator) -> list[tuple[float, PathState]]:
    """(t, state) at n random times of the profile and n/4 within its last END_SHARE."""
    T = profile.duration
    t = np.concatenate([rng.uniform(0.0, T, n),
                        rng.uniform((1.0 - END_SHARE) * T, T, max(n // 4, 1))])
    return [(float(ti), profile.state_at(float(ti))) for ti in np.sort(t)]


def run_path(p, method: str, n_states: int, seed: int, mode: str = "seamed",
             source: str | None = None) -> dict:
    """Replans from states of the first window's plan on corpus path p. mode "seamed": the
    planner's last plan is that first plan (as in the engine, whose replans start on the
    plan the planner made last; the LP then continues it at a seam); "cold": a new planner
    per replan (as after a failed replan or a fallback, when the plan in force is not the
    planner's last). source: the method that plans the first window (default `method`;
    another one implies "cold": the states of a fallback's plan)."""
    cfg, m = p.config, p.config.machine
    path = p.path()
    geo = p.geometry()
    lim = m.limits.scaled(cfg.planner.margin)
    window = horizon_length(lim, np.asarray(m.path_scale, float), cfg.planner.horizon_s)
    planner = make_planner(method)
    if source is not None and source != method:
        mode = "cold"
    tail = np.empty((0, m.limits.naxes))
    first_request = PlanRequest(path, lim, PathState(0.0), min(path.length, window), 0.0,
                                geo.feed_cap(), m.dt)
    first = (planner if source in (None, method) else make_planner(source)).plan(first_request)
    base = CommittedPlan.anchor(path, first, 0, m.dt)
    rng = np.random.default_rng(seed)
    failures, times, handovers = [], [], []
    states = states_on(first.profile, n_states, rng)
    for t, st in states:
        k = round(t / m.dt)
        st = base.state(k, m.dt)  # the engine replans from a sample of its plan
        if st.s >= path.length - S_TOL * max(path.length, 1.0):
            continue  # at the path's end: the engine asks for no replan (its tolerance)
        tail = base.samples(max(k - 2, 0), min(k, 2) + 1, m.dt).pos  # published k-2..k
        request = PlanRequest(path, lim, st, min(path.length, st.s + window), 0.0,
                              geo.feed_cap(), m.dt)
        if mode == "cold":
            planner = make_planner(method)
        elif times:
            planner.plan(first_request)  # its last plan is the one the state lies on
        t0 = time.perf_counter()
        try:
            plan = plan_checked(planner, request, k, tail, m.limits)
        except (PlanningError, ValueError, RuntimeError, ArithmeticError) as exc:
            failures.append({"k": k, "s": st.s, "v": st.v, "a": st.a,
                             "reason": str(exc)[:300]})
        else:
            if plan.handover is not None:
                handovers.append({"k": k, "s": st.s, "v": st.v, "a": st.a,
                                  **{key: plan.handover.get(key)
                                     for key in ("t", "share", "whole", "attempt")},
                                  "left_mm": request.s_end - st.s})
        times.append(time.perf_counter() - t0)
    ms = np.array(times) * 1e3 if times else np.zeros(1)
    return {"replans": len(times), "failures": len(failures), "examples": failures[:5],
            "handovers": len(handovers),
            "handovers_whole": sum(h["whole"] for h in handovers),
            "handover_share_max": max((h["share"] for h in handovers if not h["whole"]),
                                      default=0.0),
            "handover_attempt_max": max((h["attempt"] for h in handovers
                                         if h["attempt"] is not None), default=None),
            "handover_examples": handovers[:5],
            "replan_ms_p50": float(np.percentile(ms, 50)),
            "replan_ms_p99": float(np.percentile(ms, 99)),
            "first_window": min(path.length, window), "first_duration_s":
            first.profile.duration}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subset", choices=("fast", "all"), default="fast")
    ap.add_argument("--methods", default="heuristic,lp")
    ap.add_argument("--paths", default=None, help="comma-separated name globs")
    ap.add_argument("--states", type=int, default=40, help="random states per path")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--mode", choices=("seamed", "cold"), default="seamed",
                    help="seamed: replan on the planner's last plan; cold: a new planner")
    ap.add_argument("--states-from", default=None,
                    help="the method that plans the first window (default: each method "
                         "itself; another one replans cold, as after a fallback)")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args()
    globs = args.paths.split(",") if args.paths else None
    out: dict = {"meta": {"subset": args.subset, "states": args.states, "seed": args.seed,
                          "mode": args.mode, "states_from": args.states_from},
                 "paths": {}, "summary": {}}
    for p in load_corpus(args.subset, skip_long=True):  # the 100k-point ones: hours
        if globs and not any(fnmatch.fnmatch(p.name, g) for g in globs):
            continue
        row = out["paths"].setdefault(p.name, {})
        for method in args.methods.split(","):
            try:
                row[method] = run_path(p, method, args.states, args.seed, args.mode,
                                       args.states_from)
            except (PlanningError, ValueError, RuntimeError, ArithmeticError) as exc:
                row[method] = {"error": f"first window: {exc}"[:300]}
            r = row[method]
            print(f"{p.name:44s} {method:10s} " + (
                f"failures {r['failures']}/{r['replans']}  p99 {r['replan_ms_p99']:.0f} ms"
                f"  handovers {r['handovers']} (whole {r['handovers_whole']})"
                if "error" not in r else r["error"]), file=sys.stderr, flush=True)
    for method in args.methods.split(","):
        rows = {n: r[method] for n, r in out["paths"].items() if method in r}
        bad = {n: r.get("failures", "error") for n, r in rows.items()
               if "error" in r or r["failures"]}
        out["summary"][method] = {
            "paths": len(rows), "paths_with_failures": len(bad),
            "failures": int(sum(r.get("failures", 0) for r in rows.values())),
            "replans": int(sum(r.get("replans", 0) for r in rows.values())),
            "handovers": int(sum(r.get("handovers", 0) for r in rows.values())),
            "handovers_whole": int(sum(r.get("handovers_whole", 0) for r in rows.values())),
            "handover_share_max": max((r.get("handover_share_max", 0.0)
                                       for r in rows.values()), default=0.0),
            "handover_attempt_max": max((r["handover_attempt_max"] for r in rows.values()
                                         if r.get("handover_attempt_max") is not None),
                                        default=None),
            "worst": sorted(bad.items(), key=lambda kv: -1 if kv[1] == "error" else -kv[1]
                            )[:10]}
    FsPath(args.out).write_text(json.dumps(out, indent=1))
    print(json.dumps(out["summary"], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
