"""Whole-job plans of seeded pchip random walks (`bench/fuzz_paths.py`'s cases, fit
"pchip" only), with winding time and compute per case: `fuzz_paths.py` reports failures
only, this compares plans. Where every axis of a walk reverses at a point (a quarter of
the points of a 2-axis walk) the pchip fit's tangent vanishes: a cusp, which is a corner
(a stop), while the other knots are C1.

Each case is planned from rest to rest at 0.95 of its limits and judged by the
finite-difference checker at the full limits (plans over MAX_MOTION_S are not sampled:
"ok" null). Cases are drawn from a fixed seed, so two trees compare case by case:

    .venv/bin/python bench/pchip_walks.py --method lp --cases 40 --out bench/results/F.json

Stop 51 (`pchip_walks_lp_{before,after}.json`): the LP read a cusp as a C1 knot.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
import warnings
from pathlib import Path as FsPath

import numpy as np

ROOT = FsPath(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.fuzz_paths import DT, MAX_MOTION_S, build  # noqa: E402
from lookahead.checker import check_positions  # noqa: E402
from lookahead.planning.base import PathState, PlanRequest  # noqa: E402
from lookahead.sampling import sample_plan  # noqa: E402
from lookahead.stream.planners import make_planner  # noqa: E402

#: the case generator's seed (the results files of stop 51 were drawn from it)
SEED = 2026
#: a plan that takes longer than this (s of compute) is recorded as an error
TIMEOUT_S = 240


def draw_cases(n: int, seed: int = SEED) -> list[tuple]:
    """n cases (seed, axes 2-3, points 8-29, log10 step -1..1, log10 spread -1..1, pchip)."""
    rng = np.random.default_rng(seed)
    return [(int(rng.integers(10000)), int(rng.integers(2, 4)), int(rng.integers(8, 30)),
             float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), "pchip")
            for _ in range(n)]


def _timeout(signum, frame):
    raise TimeoutError(f"more than {TIMEOUT_S} s")


def run_case(case: tuple, method: str) -> dict | None:
    """{T (s of motion), compute (s), ok (checker), corners} or {error, compute, corners};
    None where the points make no path."""
    built = build(case)
    if built is None:
        return None
    path, limits = built
    corners = int(np.isin(path.breakpoints_s(), path.corners_s()).sum())
    request = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=DT)
    t0 = time.perf_counter()
    signal.alarm(TIMEOUT_S)
    try:
        result = make_planner(method).plan(request)
    except Exception as exc:  # a refused plan is a result here, whatever its type
        return {"error": f"{type(exc).__name__}: {str(exc)[:100]}",
                "compute": time.perf_counter() - t0, "corners": corners}
    finally:
        signal.alarm(0)
    compute = time.perf_counter() - t0
    duration = result.profile.duration
    ok = None
    if duration < MAX_MOTION_S:
        pos = sample_plan(path, result.profile, DT).pos
        ok = bool(check_positions(pos, limits, DT).ok)
    return {"T": duration, "compute": compute, "ok": ok, "corners": corners}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="lp")
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    signal.signal(signal.SIGALRM, _timeout)
    rows: dict[str, dict] = {}
    cases = draw_cases(args.cases)
    for k, case in enumerate(cases):
        row = run_case(case, args.method)
        if row is None:
            continue
        rows[str(case)] = row
        print(f"[{k + 1}/{len(cases)}] {case} {row}", flush=True)
    FsPath(args.out).write_text(json.dumps(rows, indent=1))
    bad = [c for c, r in rows.items() if "error" in r or r.get("ok") is False]
    print(f"{len(rows)} cases, {len(bad)} failed or over the limits")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
