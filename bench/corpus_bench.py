"""The corpus benchmark (issue 13): every corpus path x method, judged by the
finite-difference checker, against the TOPP-RA velocity+acceleration bound, the best plan
any method found and the fine-grid reference (`bench/reference.py`).

Methods (`--methods`, comma-separated):
- `heuristic`, `lp`: the whole job in one `PlanRequest` (HeuristicPlanner, LPPlanner),
- `engine-lp`, `engine-osqp`: windowed as the service runs it: a `lookahead.stream.engine.
  Engine` in fast mode fed the path's segments (all at once, as `lookahead publish` does),
  with `LPPlanner()` (HiGHS) or `LPPlanner(solver="osqp")`; fallbacks, failed replans,
  replan times (p50/p99) and the wall time per motion time,
- `engine-heuristic`: the same engine with the heuristic,
- `engine-lp-rt`, `engine-heuristic-rt`: the engine in real-time mode (replans take over
  ahead of the last sample, `lookahead.stream.ahead`; computed inline, with the batches of
  the service's worker thread),
- `nlp`: NLPPlanner on the whole job, short paths only (`NLP_MAX_*`),
- `reference`: the fine-grid jerk LP of `bench/reference.py` (offline, non-long paths).
Every plan is planned to the limits times the machine's `planner.margin` (as the engine
does) and judged by `lookahead.checker` at the full limits. One path's failure never stops
the bench: it is recorded with its reason.

Outputs: `--out` JSON (default bench/results/corpus.json; `--update` merges into it), a
plot (same name, .png) of the ratio distributions per method, and a markdown summary on
stdout (worst case first). Progress on stderr. Run from the repository root:

    .venv/bin/python bench/corpus_bench.py --subset fast
    .venv/bin/python bench/corpus_bench.py --subset all --skip-long --methods heuristic,lp
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import logging
import math
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import time
import traceback
from pathlib import Path as FsPath
from typing import Any

ROOT = FsPath(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

RESULTS = ROOT / "bench" / "results"
METHODS = ("heuristic", "lp", "engine-lp", "engine-osqp", "nlp", "reference")
ALL_METHODS = (*METHODS, "engine-heuristic", "engine-lp-rt", "engine-heuristic-rt")
#: the NLP (dense SQP, seconds per window) runs on paths at most this big
NLP_MAX_POINTS, NLP_MAX_LENGTH = 2500, 3000.0
#: samples per checker/sampling chunk (bounded memory on long jobs)
CHUNK = 20_000
#: the result file is rewritten at least this often during a run (s)
SAVE_EVERY_S = 30.0
#: toppra grid points per path point, within [MIN, MAX] (the bound's resolution)
BOUND_GRID = (2000, 20000)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --- one task ---------------------------------------------------------------------------


class _TimeoutError(Exception):
    pass


def _alarm(signum, frame):
    raise _TimeoutError()


class TimedPlanner:
    """Forwards to a planner and records the wall time of each plan call (s)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.name = inner.name
        self.times: list[float] = []

    def plan(self, request, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return self.inner.plan(request, *args, **kwargs)
        finally:
            self.times.append(time.perf_counter() - t0)

    def __getattr__(self, item: str):
        return getattr(self.inner, item)


class AheadRecorder:
    """An inline executor for a real-time engine that records, per replan computed
    ahead, the motion time between the last produced sample and its take-over (`ahead_s`)
    and how long it took (`compute_s`): a service would wait where compute_s > ahead_s."""

    def __init__(self) -> None:
        from lookahead.stream.ahead import InlineExecutor

        self.inline = InlineExecutor()
        self.k_next = 0  # the next sample the engine produces (kept by the caller)
        self.dt = 0.0
        self.rows: list[tuple[float, float]] = []

    def submit(self, fn, /, *args, **kwargs):
        from lookahead.stream.ahead import plan_with_fallback

        if fn is not plan_with_fallback:  # the engine's other tasks (planners' forget)
            return self.inline.submit(fn, *args, **kwargs)
        k_at = args[3]  # plan_with_fallback(planner, fallback, request, k_at, ...)
        t0 = time.perf_counter()
        future = self.inline.submit(fn, *args, **kwargs)
        self.rows.append(((k_at - self.k_next + 1) * self.dt, time.perf_counter() - t0))
        return future


class _Collect(logging.Handler):
    """Keeps the first few WARNING+ messages of the engine (fallback and replan reasons)."""

    def __init__(self, keep: int = 5) -> None:
        super().__init__(logging.WARNING)
        self.keep = keep
        self.messages: list[str] = []
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.count += 1
        if len(self.messages) < self.keep:
            self.messages.append(record.getMessage()[:400])


def _corpus_path(name: str):
    from bench.corpus import load_corpus

    found = [p for p in load_corpus("all") if p.name == name]
    if not found:
        raise KeyError(f"no corpus path {name!r}")
    return found[0]


def _check_profile(path, profile, limits, dt) -> dict:
    """Sample a whole-job profile at k dt and run the checker (in chunks)."""
    from lookahead.checker import LimitChecker
    from lookahead.sampling import sample_profile, sample_times

    times = sample_times(profile.duration, dt)
    checker = LimitChecker(limits, dt)
    end_err = 0.0
    for a in range(0, len(times), CHUNK):
        smp = sample_profile(path, profile, times[a:a + CHUNK])
        checker.feed(smp.pos)
        if a + CHUNK >= len(times):
            end = path.eval_s(np.array([path.length]), order=0)[0, 0]
            end_err = float(np.max(np.abs(smp.pos[-1] - end)))
    rep = checker.report()
    return {"violations": rep.violations, "peak": rep.peak_fraction,
            # the motion as the engine's streams count it: (samples - 1) dt
            "winding_sampled_s": (len(times) - 1) * dt,
            "first_violation": None if rep.first is None else rep.first._asdict(),
            "end_error": end_err}


def _request(p, path, limits):
    from lookahead.planning.base import PathState, PlanRequest

    geo = p.geometry()
    return PlanRequest(path, limits, PathState(0.0), path.length,
                       feed_cap=geo.feed_cap(), dt=p.config.machine.dt)


def run_whole(p, method: str) -> dict:
    """heuristic / lp / nlp on the whole job."""
    m = p.config.machine
    path = p.path()
    if method == "nlp" and (p.npoints > NLP_MAX_POINTS or path.length > NLP_MAX_LENGTH):
        return {"skipped": f"nlp: only paths <= {NLP_MAX_POINTS} points and "
                           f"<= {NLP_MAX_LENGTH:g} path units"}
    plan_limits = m.limits.scaled(p.config.planner.margin)
    if method == "heuristic":
        from lookahead.planning.heuristic import HeuristicPlanner

        planner = HeuristicPlanner(margin=1.0)
    elif method == "lp":
        from lookahead.planning.lp import LPPlanner

        planner = LPPlanner()
    elif method == "nlp":
        from lookahead.planning.nlp import NLPPlanner

        planner = NLPPlanner()
    else:
        raise ValueError(method)
    request = _request(p, path, plan_limits)
    t0 = time.perf_counter()
    result = planner.plan(request)
    compute = time.perf_counter() - t0
    out = {"winding_s": result.profile.duration, "compute_s": compute}
    out.update(_check_profile(path, result.profile, m.limits, m.dt))
    return out


def engine_batches(engine, idle_limit: int = 100_000):
    """The batches of an Engine in fast mode up to and including the final one (stops
    early when it is idle `idle_limit` calls in a row or no longer busy)."""
    idle = 0
    while True:
        batch = engine.next_batch()
        if batch is None:
            idle += 1
            if idle > idle_limit or not engine.busy:
                return
            continue
        idle = 0
        yield batch
        if batch.final:
            return


def run_engine(p, method: str) -> dict:
    """The service's engine in fast mode, fed every segment at once; until the final batch."""
    from lookahead.checker import LimitChecker
    from lookahead.stream.engine import Engine

    realtime = method.endswith("-rt")
    method = method.removesuffix("-rt")
    if method == "engine-heuristic":
        from lookahead.planning.heuristic import HeuristicPlanner

        inner = HeuristicPlanner(margin=1.0)
    else:
        from lookahead.planning.lp import LPPlanner

        inner = LPPlanner(solver="osqp" if method == "engine-osqp" else "highs")
    planner = TimedPlanner(inner)
    handler = _Collect()
    elog = logging.getLogger("lookahead")
    elog.addHandler(handler)
    try:
        m = p.config.machine
        segments = p.segments
        t0 = time.perf_counter()
        ahead = AheadRecorder()
        ahead.dt = m.dt
        engine = Engine(p.config, planner, realtime=realtime, executor=ahead)
        events: list = []
        for seg in segments:
            events += engine.submit(seg)
        checker = LimitChecker(m.limits, m.dt)
        samples, last_pos, final = 0, None, False
        for batch in engine_batches(engine):
            checker.feed(batch.pos)
            samples += batch.n
            ahead.k_next = samples
            last_pos = batch.pos[-1]
            final = batch.final
        wall = time.perf_counter() - t0
        events += engine.drain_events()
    finally:
        elog.removeHandler(handler)
    rep = checker.report()
    bad = [e for e in events if e.type in ("rejected", "fault")]
    finished = [e for e in events if e.type == "job_finished"]
    aborted = any(e.extra.get("aborted") for e in finished)
    plan_ms = np.array(planner.times) * 1e3 if planner.times else np.zeros(1)
    out: dict[str, Any] = {
        "winding_s": max(samples - 1, 0) * m.dt, "compute_s": wall, "samples": samples,
        "final": final, "aborted": aborted, "fallbacks": engine.fallbacks,
        "replans": engine.replans, "replan_failures": engine.replan_failures,
        "plans": len(planner.times), "replan_ms_p50": float(np.percentile(plan_ms, 50)),
        "replan_ms_p99": float(np.percentile(plan_ms, 99)),
        "replan_ms_max": float(np.max(plan_ms)),
        "ahead_plans": len(ahead.rows),
        "ahead_late": sum(c > a for a, c in ahead.rows),
        "ahead_min_slack_s": min((a - c for a, c in ahead.rows), default=None),
        "events": [f"{e.type}: {e.extra.get('reason', '')}"[:300] for e in bad][:5],
        "warnings": handler.count, "warning_messages": handler.messages,
        "violations": rep.violations, "peak": rep.peak_fraction,
        "first_violation": None if rep.first is None else rep.first._asdict()}
    path = p.path()
    end = path.eval_s(np.array([path.length]), order=0)[0, 0]
    out["end_error"] = float(np.max(np.abs(last_pos - end))) if last_pos is not None else None
    if not final or aborted or bad:
        out["error"] = ("the job did not end normally: " +
                        ("no final batch; " if not final else "") +
                        ("aborted; " if aborted else "") + "; ".join(out["events"]))
    return out


def run_bound(p) -> dict:
    from lookahead.planning.bounds import toppra_time_bound

    path = p.path()
    grid = int(min(max(2 * p.npoints, BOUND_GRID[0]), BOUND_GRID[1]))
    t0 = time.perf_counter()
    bound = toppra_time_bound(path, p.config.machine.limits, gridpoints=grid,
                              feed_cap=p.geometry().feed_cap())
    return {"bound_s": bound, "compute_s": time.perf_counter() - t0, "gridpoints": grid}


def run_reference(p) -> dict:
    from bench import reference

    if p.long:
        return {"skipped": "reference: long paths are not run (offline cost)"}
    m = p.config.machine
    path = p.path()
    t0 = time.perf_counter()
    ref = reference.plan_reference(path, m.limits.scaled(p.config.planner.margin), m.dt,
                                   check_limits=m.limits, feed_cap=p.geometry().feed_cap())
    out = ref.to_dict()
    out["compute_s"] = time.perf_counter() - t0
    return out


def run_task(task: tuple[str, str, float]) -> tuple[str, str, dict]:
    """One (path, method); never raises: failures come back as {"error": reason}."""
    name, method, timeout = task
    logging.getLogger("lookahead").setLevel(logging.WARNING)
    logging.getLogger("lookahead").propagate = False

    def task() -> dict:
        p = _corpus_path(name)
        if method == "bound":
            return run_bound(p)
        if method == "reference":
            return run_reference(p)
        if method.startswith("engine-"):
            return run_engine(p, method)
        return run_whole(p, method)

    return name, method, run_guarded(task, timeout)


def run_guarded(task, timeout: float) -> dict:
    """task() (a result dict) under a SIGALRM timeout; never raises: a timeout or an
    exception comes back as {"error": reason, ...}; "task_s" is its wall time."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(max(1, int(timeout)))
    t0 = time.perf_counter()
    try:
        out = task()
    except _TimeoutError:
        out = {"error": f"timeout: more than {timeout:g} s (task killed)"}
    except Exception as exc:  # a bad path must not stop the bench
        tb = traceback.extract_tb(exc.__traceback__)
        where = f"{tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
        out = {"error": f"{type(exc).__name__}: {exc}"[:500], "where": where}
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    out.setdefault("task_s", time.perf_counter() - t0)
    return out


# --- aggregation --------------------------------------------------------------------------


def failed(row: dict | None) -> bool:
    """A failure: an exception, a checker violation, a fallback or a failed replan."""
    if row is None or "skipped" in row:
        return False
    return bool(row.get("error") or row.get("violations") or row.get("fallbacks")
                or row.get("replan_failures"))


def usable(row: dict | None) -> bool:
    return row is not None and "winding_s" in row and not row.get("error") \
        and not row.get("violations")


#: the whole-job method of the same planner a service engine's windowed plans are judged
#: against (OSQP has no whole-job method here)
WHOLE_JOB_OF = {"engine-lp": "lp", "engine-heuristic": "heuristic"}


def finish_path(entry: dict) -> None:
    """Per path: the best checked plan and each method's ratios."""
    methods = entry["methods"]
    bound = (entry.get("bound") or {}).get("bound_s")
    ok = {k: r["winding_s"] for k, r in methods.items() if usable(r)}
    best = min(ok.values()) if ok else None
    ref = methods.get("reference")
    ref_s = ref["winding_s"] if usable(ref) else None
    entry["bound_s"], entry["best_s"], entry["reference_s"] = bound, best, ref_s
    entry["best_method"] = min(ok, key=ok.get) if ok else None
    for r in methods.values():
        if "winding_s" not in r:
            continue
        T = r["winding_s"]
        r["ratio_bound"] = T / bound if bound else None
        r["ratio_best"] = T / best if best else None
        r["ratio_reference"] = T / ref_s if ref_s else None
        r["x_realtime"] = T / r["compute_s"] if r.get("compute_s") else None
        r["failed"] = failed(r)
    for m, r in methods.items():
        # the windowed plan against the same planner's whole job, both in samples (a
        # whole-job time of 45.5 ms streams as 46 samples: 1 % on the shortest paths)
        whole = methods.get(WHOLE_JOB_OF.get(m.removesuffix("-rt"), ""))
        if "winding_s" in r and usable(whole) and whole.get("winding_sampled_s"):
            r["ratio_whole"] = r["winding_s"] / whole["winding_sampled_s"]


def _stat(values: list[float], worst_is_max: bool = True) -> tuple[float, float] | None:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if not vals:
        return None
    return (max(vals) if worst_is_max else min(vals)), float(np.median(vals))


def summary(paths: dict[str, dict], methods: list[str]) -> dict[str, dict]:
    out = {}
    for m in methods:
        rows = [(n, e["methods"][m]) for n, e in paths.items() if m in e["methods"]]
        ran = [(n, r) for n, r in rows if "skipped" not in r]
        if not ran:
            continue
        errors = [(n, r["error"]) for n, r in ran if r.get("error")]
        viol = [n for n, r in ran if r.get("violations")]
        fb = sum(r.get("fallbacks", 0) for _, r in ran)
        rf = sum(r.get("replan_failures", 0) for _, r in ran)
        s: dict[str, Any] = {
            "paths": len(ran), "failed_paths": sum(failed(r) for _, r in ran),
            "errors": len(errors), "violating_paths": len(viol), "fallbacks": fb,
            "replan_failures": rf,
            "error_examples": [f"{n}: {e}" for n, e in errors[:8]],
        }
        for key, worst_max in (("ratio_bound", True), ("ratio_best", True),
                               ("ratio_whole", True),
                               ("ratio_reference", True), ("x_realtime", False),
                               ("replan_ms_p99", True)):
            pairs = [(n, r.get(key)) for n, r in ran if usable(r) and r.get(key) is not None
                     and (key != "x_realtime" or r.get("winding_s", 0) > 1.0)]
            st = _stat([v for _, v in pairs], worst_max)
            if st:
                pick = max if worst_max else min
                s[key] = {"worst": st[0], "median": st[1],
                          "worst_path": pick(pairs, key=lambda t: t[1])[0]}
        slow = [(n, r.get("x_realtime")) for n, r in ran
                if usable(r) and r.get("winding_s", 0) > 1.0 and r.get("x_realtime")]
        s["below_100x_realtime"] = sum(1 for _, x in slow if x < 100)
        out[m] = s
    return out


def _cell(s: dict, key: str, fmt: str = "{:.3f}") -> str:
    v = s.get(key)
    if not v:
        return "-"
    return f"{fmt.format(v['worst'])} / {fmt.format(v['median'])}"


def table(summ: dict[str, dict]) -> str:
    """Markdown: one row per method, worst first (worst / median)."""
    lines = ["| method | paths | failed (errors, violating, fallbacks, failed replans) "
             "| / v+a bound worst / median | / best worst / median "
             "| / reference worst / median | windowed / whole job (in samples) worst / median "
             "| x real time (> 1 s of motion) worst / median "
             "| replan p99 ms worst / median |",
             "|---|---|---|---|---|---|---|---|---|"]
    order = sorted(summ, key=lambda m: -summ[m]["failed_paths"])
    for m in order:
        s = summ[m]
        lines.append(
            f"| {m} | {s['paths']} | **{s['failed_paths']}** ({s['errors']}, "
            f"{s['violating_paths']}, {s['fallbacks']}, {s['replan_failures']}) "
            f"| {_cell(s, 'ratio_bound')} | {_cell(s, 'ratio_best')} "
            f"| {_cell(s, 'ratio_reference')} | {_cell(s, 'ratio_whole')} "
            f"| {_cell(s, 'x_realtime', '{:.0f}')} "
            f"| {_cell(s, 'replan_ms_p99', '{:.0f}')} |")
    return "\n".join(lines)


def worst_cases(paths: dict[str, dict], n: int = 15) -> str:
    """Markdown list of the worst path x method cases: failures first, then / best."""
    rows = []
    for name, e in paths.items():
        for m, r in e["methods"].items():
            if "skipped" in r:
                continue
            if failed(r):
                why = r.get("error") or (f"{r.get('violations', 0)} violations, "
                                         f"{r.get('fallbacks', 0)} fallbacks, "
                                         f"{r.get('replan_failures', 0)} failed replans")
                rows.append((0, -1e9, f"| {name} | {m} | FAILED: {why[:160]} |"))
            elif r.get("ratio_best"):
                rows.append((1, -r["ratio_best"], f"| {name} | {m} | / best "
                             f"{r['ratio_best']:.3f}, / bound "
                             f"{(r.get('ratio_bound') or float('nan')):.3f} |"))
    rows.sort()
    head = ["| path | method | what |", "|---|---|---|"]
    return "\n".join(head + [r[2] for r in rows[:n]])


def figure(paths: dict[str, dict], methods: list[str], out_png: FsPath) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    for ax, key, title in ((axes[0], "ratio_bound", "winding time / TOPP-RA v+a bound"),
                           (axes[1], "ratio_best", "winding time / best checked plan")):
        data, labels, fails = [], [], []
        for m in methods:
            vals = [e["methods"][m].get(key) for e in paths.values()
                    if m in e["methods"] and usable(e["methods"][m])]
            vals = [v for v in vals if v is not None]
            nfail = sum(failed(e["methods"].get(m)) for e in paths.values())
            if vals or nfail:
                data.append(vals or [np.nan])
                labels.append(m)
                fails.append(nfail)
        if not data:
            continue
        ax.boxplot(data, whis=(0, 100), showfliers=False)
        rng = np.random.default_rng(0)
        for i, vals in enumerate(data, start=1):
            ax.scatter(i + 0.08 * rng.standard_normal(len(vals)), vals, s=9, alpha=0.6)
        ax.set_xticks(range(1, len(labels) + 1),
                      [f"{m}\n{f} failed" for m, f in zip(labels, fails, strict=True)],
                      fontsize=8)
        ax.set_yscale("log")
        ax.set_title(title)
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle(f"corpus: {len(paths)} paths (whiskers: min..max; dots: paths)")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)


def git_state() -> dict:
    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                                  timeout=20).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    status = git("status", "--porcelain")
    import lookahead

    return {"head": git("rev-parse", "HEAD"), "head_subject": git("log", "-1", "--format=%s"),
            "dirty_files": len(status.splitlines()) if status else 0,
            "diff_sha256": _sha(git("diff", "HEAD")),
            "lookahead_from": str(FsPath(lookahead.__file__).parent),
            "lookahead_in_work_tree": FsPath(lookahead.__file__).resolve().is_relative_to(ROOT),
            "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def _sha(text: str) -> str:
    import hashlib

    return hashlib.sha256(text.encode()).hexdigest()


# --- main ---------------------------------------------------------------------------------


def report(path: FsPath, plot: bool = True) -> int:
    """Re-print the summary of a result file (recomputing the ratios) and re-plot it."""
    doc = json.loads(path.read_text())
    paths = doc["paths"]
    for e in paths.values():
        e.setdefault("methods", {})
        finish_path(e)
    methods = [m for m in ALL_METHODS if any(m in e["methods"] for e in paths.values())]
    if plot:
        figure(paths, methods, path.with_suffix(".png"))
    print(table(summary(paths, methods)))
    print()
    print(worst_cases(paths))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subset", choices=("fast", "all"), default="fast")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"comma-separated, of {', '.join(ALL_METHODS)} "
                         f"(default {','.join(METHODS)})")
    ap.add_argument("--paths", default=None,
                    help="only paths whose name matches one of these comma-separated globs")
    ap.add_argument("--skip-long", action="store_true", help="skip the 100k+ point paths")
    ap.add_argument("--out", default=str(RESULTS / "corpus.json"))
    ap.add_argument("--update", action="store_true",
                    help="merge into an existing --out (replacing the rows run now)")
    ap.add_argument("--workers", type=int, default=2, help="processes (at most 2)")
    ap.add_argument("--task-timeout", type=float, default=600.0,
                    help="seconds per path x method before it counts as failed")
    ap.add_argument("--no-plot", action="store_true")
    ap.add_argument("--report", metavar="JSON", default=None,
                    help="only re-print the summary (and re-plot) from an existing result")
    args = ap.parse_args(argv)
    if args.report:
        return report(FsPath(args.report), plot=not args.no_plot)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in methods if m not in ALL_METHODS]
    if unknown:
        ap.error(f"unknown methods {unknown} (known: {', '.join(ALL_METHODS)})")

    from bench.corpus import load_corpus

    corpus = load_corpus(args.subset, skip_long=args.skip_long)
    if args.paths:
        globs = [g.strip() for g in args.paths.split(",") if g.strip()]
        corpus = [p for p in corpus if any(fnmatch.fnmatchcase(p.name, g) for g in globs)]
    if not corpus:
        ap.error("no corpus path matches")
    out_path = FsPath(args.out)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {"paths": {}}
    if args.update and out_path.exists():
        doc = json.loads(out_path.read_text())
    paths = doc.setdefault("paths", {})
    for p in corpus:
        e = paths.setdefault(p.name, {"methods": {}})
        e.update({"family": p.family, "notes": p.notes, "long": p.long, "fast": p.fast,
                  "axes": list(p.config.machine.axes), "margin": p.config.planner.margin})
    # biggest first, so the slow tasks start early; the bound with every path
    tasks = [(p.name, m, args.task_timeout) for p in corpus for m in ("bound", *methods)]
    size = {p.name: (p.long, len(p.notes)) for p in corpus}
    tasks.sort(key=lambda t: (not size[t[0]][0], t[1] != "reference"))
    log(f"corpus bench: {len(corpus)} paths x {len(methods)} methods (+ bound), "
        f"{len(tasks)} tasks, {min(args.workers, 2)} workers")
    t0 = time.perf_counter()
    workers = max(1, min(args.workers, 2))
    done, last_save = 0, time.perf_counter()
    if workers == 1:  # in this process (tests; no pool)
        results = map(run_task, tasks)
        pool = None
    else:
        pool = mp.get_context("fork").Pool(workers, maxtasksperchild=20)
        results = pool.imap_unordered(run_task, tasks)
    try:
        for name, method, row in results:
            done += 1
            e = paths[name]
            if method == "bound":
                e["bound"] = row
            else:
                e["methods"][method] = row
            what = row.get("error") or row.get("skipped") or (
                f"{row.get('winding_s', row.get('bound_s', float('nan'))):.3f} s, "
                f"{row.get('violations', 0)} viol, {row.get('fallbacks', 0)} fb, "
                f"compute {row.get('compute_s', 0):.2f} s")
            log(f"[{done}/{len(tasks)} {time.perf_counter() - t0:6.0f}s] {name} {method}: "
                f"{what[:200]}")
            if time.perf_counter() - last_save > SAVE_EVERY_S:  # a killed run keeps rows
                out_path.write_text(json.dumps(doc, indent=1, default=float))
                last_save = time.perf_counter()
    finally:
        if pool is not None:
            pool.terminate()
            pool.join()
    for e in paths.values():
        e.setdefault("methods", {})
        finish_path(e)
    all_methods = [m for m in ALL_METHODS if any(m in e["methods"] for e in paths.values())]
    summ = summary(paths, all_methods)
    doc["meta"] = {"git": git_state(), "subset": args.subset, "methods": all_methods,
                   "skip_long": args.skip_long, "paths_glob": args.paths,
                   "wall_s": time.perf_counter() - t0, "workers": workers,
                   "cpu_count": os.cpu_count(),
                   "judged_by": "lookahead.checker at the full limits; plans at limits x "
                                "planner.margin",
                   "bound": "lookahead.planning.bounds.toppra_time_bound (v+a, full limits, "
                            "the segments' feed caps)"}
    doc["summary"] = summ
    out_path.write_text(json.dumps(doc, indent=1, default=float))
    if not args.no_plot:
        try:
            figure(paths, all_methods, out_path.with_suffix(".png"))
        except Exception as exc:  # the numbers matter more than the picture
            log(f"plot failed: {exc}")
    print(table(summ))
    print()
    print(worst_cases(paths))
    log(f"wrote {out_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
