"""Fuzzing the planners on random paths nobody tuned on (issues 13/14): seeded random walks
of 4-60 points in 2-4 axes (unit path scale), each axis's step size and limits drawn over
decades, fitted `cubic`, `linear` (tolerance 5 % of the step) or `pchip`; each planned
whole job from rest to rest at 0.95 of the limits and judged by the finite-difference
checker at the full limits.

A case is (seed, axes, points, log10 step, log10 axis spread, fit): `--case` replays one.
Written to find what the corpus does not hold: stop 38 found with it that the heuristic
ignored C1-knot jumps on pchip paths where one knot nearly stops the parametrization (7 of
200 paths broke the jerk limit up to 12x; `tests/test_heuristic_c1_knot_caps.py`), and
that the whole-job LP fails on some of the same paths ("highs returned Infeasible", one
plan 0.17 % over the jerk limit; open). Results: one line per failure and a summary, on
stdout (hypothesis draws new cases each run: quote the seed range or the cases found).

    .venv/bin/python bench/fuzz_paths.py --method heuristic --examples 200
    .venv/bin/python bench/fuzz_paths.py --method lp --examples 40
    .venv/bin/python bench/fuzz_paths.py --case "(922, 2, 27, 0.2042, -1.348, 'pchip')"
"""

from __future__ import annotations

import argparse
import ast
import sys
import time
import warnings

import numpy as np

from lookahead.checker import check_positions
from lookahead.geometry.fits import fit_path
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanRequest
from lookahead.sampling import sample_plan

DT = 0.001
#: plans longer than this (s of motion) are not sampled and checked (compute bound)
MAX_MOTION_S = 200.0


def build(case: tuple) -> tuple | None:
    """(path, limits) of a case, or None where the points do not make a path."""
    seed, naxes, npoints, log_step, log_spread, fit = case
    rng = np.random.default_rng(seed)
    steps = (rng.normal(size=(npoints, naxes)) * 10**log_step
             * 10 ** (rng.uniform(-1, 1, size=naxes) * abs(log_spread)))
    points = np.cumsum(steps, axis=0)
    vmax = 10 ** rng.uniform(0, 3, naxes)
    amax = vmax * 10 ** rng.uniform(0.5, 1.5, naxes)
    jmax = amax * 10 ** rng.uniform(0.5, 1.5, naxes)
    try:
        path = fit_path(points, np.ones(naxes), fit,
                        0.05 * 10**log_step if fit == "linear" else None)
    except (ValueError, TypeError):
        return None
    if not path.length > 0.0:
        return None
    return path, AxisLimits(vmax, amax, jmax)


def judge(case: tuple, method: str) -> str | None:
    """None if the case plans within the limits (or is no path), else what went wrong."""
    from lookahead.stream.planners import make_planner

    built = build(case)
    if built is None:
        return None
    path, limits = built
    request = PlanRequest(path, limits.scaled(0.95), PathState(0.0), path.length, dt=DT)
    try:
        result = make_planner(method).plan(request)
    except Exception as exc:  # a refused plan is a finding here, whatever its type
        return f"plan: {type(exc).__name__}: {str(exc)[:120]}"
    if result.profile.duration > MAX_MOTION_S:
        return None
    report = check_positions(sample_plan(path, result.profile, DT).pos, limits, DT)
    return None if report.ok else f"check: {report.first}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", choices=("heuristic", "lp"), default="heuristic")
    ap.add_argument("--examples", type=int, default=100)
    ap.add_argument("--case", default=None, help="replay one case (a Python tuple)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)  # degenerate fits overflow in numpy
    if args.case:
        print(judge(ast.literal_eval(args.case), args.method) or "ok")
        return 0
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    cases = st.tuples(st.integers(0, 10**6), st.integers(2, 4), st.integers(4, 60),
                      st.floats(-1, 2), st.floats(-1.5, 1.5),
                      st.sampled_from(["cubic", "linear", "pchip"]))
    found: list[tuple[tuple, str]] = []
    count = [0]

    @settings(max_examples=args.examples, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(cases)
    def run(case: tuple) -> None:
        count[0] += 1
        problem = judge(case, args.method)
        if problem is not None:
            found.append((case, problem))
            print(f"{case!r}: {problem}", flush=True)

    t0 = time.perf_counter()
    run()
    print(f"{args.method}: {count[0]} cases, {len(found)} failed "
          f"({time.perf_counter() - t0:.0f} s)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
