"""The LP's work on corpus paths as the service plans them, in counts that do not depend on
the machine's load: LP solves, simplex iterations, seam attempts that failed, plans from
scratch. For before/after claims on a shared, noisy machine, beside (not instead of)
side-by-side timings (`farm-bench`, `bench/lp_quality.py`).

Every named path goes through the engine as `bench/corpus_bench.py`'s engine-lp (HiGHS);
the counts come from wrapping the planner's methods, so the planner is unchanged. Per
path: winding time, fallbacks, checker violations, plans, LP solves, simplex iterations,
seam attempts (`LPPlanner._plan_frozen`, `_plan_half_frozen`, `_plan_seam`) that failed
and that planned, plans from scratch (`_plan_released`), and the process CPU time (load
dependent: only comparable within one run).

    .venv/bin/python bench/lp_work.py --paths 'cam-fp-*,c-rand3-*' --out F.json
    # the same on another tree, for a before/after table:
    env PYTHONPATH=/tmp/old/service .venv/bin/python bench/lp_work.py ... --out G.json
    .venv/bin/python bench/lp_work.py --compare G.json F.json
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import time
from pathlib import Path as FsPath

ROOT = FsPath(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

COUNTS = ("solves", "iterations", "seam_failed", "seam_planned", "from_scratch")
SEAM_ATTEMPTS = ("_plan_frozen", "_plan_half_frozen", "_plan_seam")


def instrument(counts: dict[str, int]) -> None:
    """Wrap the LP planner's solver and attempt methods to count into `counts`."""
    from lookahead.planning.lp import planner as lp_planner
    from lookahead.planning.lp import solve as lp_solve

    backend = lp_solve.HighsBackend
    solve = backend.solve

    def counted_solve(self, lp, z0=None):
        out = solve(self, lp, z0)
        counts["solves"] += 1
        counts["iterations"] += out.iterations
        return out

    backend.solve = counted_solve
    cls = lp_planner.LPPlanner
    depth = [0]  # attempts call one another (half-frozen -> frozen): count the outer one
    for name in SEAM_ATTEMPTS:
        attempt = getattr(cls, name)

        def counted_attempt(self, *args, _attempt=attempt, **kwargs):
            depth[0] += 1
            try:
                result = _attempt(self, *args, **kwargs)
            except lp_planner.PlanningError:
                counts["seam_failed"] += depth[0] == 1
                raise
            finally:
                depth[0] -= 1
            counts["seam_planned"] += depth[0] == 0
            return result

        setattr(cls, name, counted_attempt)
    released = cls._plan_released

    def counted_released(self, *args, **kwargs):
        counts["from_scratch"] += 1
        return released(self, *args, **kwargs)

    cls._plan_released = counted_released


def run(names: list[str]) -> dict[str, dict]:
    from bench.corpus_bench import _corpus_path, run_engine

    counts = dict.fromkeys(COUNTS, 0)
    instrument(counts)
    rows = {}
    for name in names:
        counts.update(dict.fromkeys(COUNTS, 0))
        cpu = time.process_time()
        r = run_engine(_corpus_path(name), "engine-lp")
        rows[name] = {**counts, "cpu_s": time.process_time() - cpu,
                      "winding_s": r["winding_s"], "fallbacks": r["fallbacks"],
                      "violations": r["violations"], "plans": r["plans"],
                      "error": r.get("error")}
        print(name, json.dumps(rows[name]), file=sys.stderr, flush=True)
    return rows


def compare(before: dict, after: dict) -> str:
    """A before/after table (ratios after / before), worst winding change first."""
    lines = ["path | winding before -> after | solves | iterations | seam failed | "
             "from scratch | cpu (same run only)"]
    names = [n for n in before["paths"] if n in after["paths"]]
    names.sort(key=lambda n: -after["paths"][n]["winding_s"] / before["paths"][n]["winding_s"])
    for n in names:
        b, a = before["paths"][n], after["paths"][n]
        lines.append(
            f"{n} | {b['winding_s']:.3f} -> {a['winding_s']:.3f} "
            f"({100 * (a['winding_s'] / b['winding_s'] - 1):+.2f} %) | "
            f"{b['solves']} -> {a['solves']} | {b['iterations']} -> {a['iterations']} "
            f"({a['iterations'] / max(b['iterations'], 1):.2f}x) | "
            f"{b['seam_failed']} -> {a['seam_failed']} | "
            f"{b['from_scratch']} -> {a['from_scratch']} | "
            f"{b['cpu_s']:.1f} -> {a['cpu_s']:.1f} s")
    tb = sum(before["paths"][n]["iterations"] for n in names)
    ta = sum(after["paths"][n]["iterations"] for n in names)
    lines.append(f"iterations summed: {tb} -> {ta} ({ta / max(tb, 1):.2f}x)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--paths", help="comma-separated globs of corpus path names")
    ap.add_argument("--out", help="result JSON")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"),
                    help="print the table of two result files and exit")
    args = ap.parse_args(argv)
    if args.compare:
        before, after = (json.loads(FsPath(f).read_text()) for f in args.compare)
        print(compare(before, after))
        return 0
    if not args.paths or not args.out:
        ap.error("--paths and --out (or --compare)")
    from bench.corpus import load_corpus

    globs = [g.strip() for g in args.paths.split(",") if g.strip()]
    names = [p.name for p in load_corpus("all", skip_long=True)
             if any(fnmatch.fnmatchcase(p.name, g) for g in globs)]
    import lookahead

    rows = run(names)
    doc = {"meta": {"lookahead_from": str(FsPath(lookahead.__file__).parent),
                    "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                    "what": __doc__.split("\n")[0]},
           "paths": rows}
    FsPath(args.out).write_text(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
