"""Path fidelity benchmark (issue 15): how far each fit leaves the programmed polyline, and
what following it costs in cycle time and corner speed, against exact stops.

Paths: the issue's zig-zag (7 points, 90 deg corners, default winder); the CAM programs of
the corpus (fiberpath G-code and the fiberpath-style generator: 1 mm moves, locks where the
mandrel turns ~558 deg with X held); with `--corpus`, every `points` path of the fast corpus.
Fits: cubic, pchip (interpolating), linear at tolerances 0 (exact stops), 0.05, 0.5 mm,
smooth at 0.05 mm. Per path and fit: cycle time (heuristic planner, as the engine plans:
limits times the configured margin; the LP's time or failure beside it), the finite-
difference checker's verdict on the samples, the largest distance of the samples from the
polyline (lookahead.geometry.deviation), how far X runs past the program's X range (the
cubic's swing at the locks), the lowest feed at the programmed corners (the zig-zag's), and
the fitting time.

Writes bench/results/fidelity.json (or --out). Run from the repository root:
    nice -n 10 .venv/bin/python bench/fidelity_bench.py [--quick] [--no-lp] [--corpus]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path as FsPath

import numpy as np

ROOT = FsPath(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lookahead.checker import check_positions  # noqa: E402
from lookahead.config import Config, default_config  # noqa: E402
from lookahead.geometry.deviation import polyline_distance  # noqa: E402
from lookahead.geometry.fits import fit_path  # noqa: E402
from lookahead.planning.base import PathState, PlanRequest  # noqa: E402
from lookahead.sampling import sample_plan  # noqa: E402
from lookahead.stream.planners import make_planner  # noqa: E402

RESULTS = ROOT / "bench" / "results"
ZIGZAG = np.array([(0, 0), (200, 0), (200, 360), (400, 360), (400, 720), (600, 720), (0, 1440)],
                  dtype=float)
#: (label, fit, tolerance mm)
FITS = [("cubic", "cubic", 0.05), ("pchip", "pchip", 0.05), ("exact-stop", "linear", 0.0),
        ("linear-0.05", "linear", 0.05), ("linear-0.5", "linear", 0.5),
        ("smooth-0.05", "smooth", 0.05)]
CAM_PATHS = ("cam-style-R50-a45-L200", "cam-fp-hel45-D60-L120-noB", "cam-fp-hoop-D60-L80-noB")


def job_points(segments) -> np.ndarray:
    """The point stream of a job's `points` segments, repeats dropped."""
    pts = np.vstack([s.points for s in segments])
    keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0, axis=1)])
    return pts[keep]


def corner_feeds(path, profile, corners: np.ndarray) -> list[float]:
    """The feed (path units/s) where the motion passes each programmed corner (the sample
    nearest it on the path, 0.1 ms apart)."""
    t = np.arange(0.0, profile.duration, 1e-4)
    s, v = profile.at(t)[:2]
    x = path.eval_s(s, 0)[0]
    out = []
    for c in corners:
        i = int(np.argmin(np.linalg.norm((x - c) * path.path_scale, axis=1)))
        out.append(float(v[i]))
    return out


def run_fit(points: np.ndarray, config: Config, label: str, fit: str, tol: float,
            use_lp: bool, corners: np.ndarray | None) -> dict:
    m = config.machine
    scale = np.asarray(m.path_scale)
    t0 = time.perf_counter()
    path = fit_path(points, scale, fit, tol)
    out: dict = {"fit": label, "tolerance": tol, "fit_s": time.perf_counter() - t0,
                 "pieces": int(len(path.breakpoints_s()) - 1), "length": path.length}
    limits = m.limits.scaled(config.planner.margin)
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=m.dt)
    for method in ("heuristic", "lp") if use_lp else ("heuristic",):
        t0 = time.perf_counter()
        try:
            result = make_planner(method).plan(request)
        except Exception as exc:  # a failure is a result here: recorded, not raised
            out[method] = {"failed": f"{type(exc).__name__}: {exc}"}
            continue
        plan_s = time.perf_counter() - t0
        samples = sample_plan(path, result.profile, m.dt)
        check = check_positions(samples.pos, m.limits, m.dt)
        dev = polyline_distance(samples.pos, points, scale)
        x_lo, x_hi = float(np.min(points[:, 0])), float(np.max(points[:, 0]))
        rec = {"time_s": result.profile.duration, "plan_s": plan_s, "checker_ok": check.ok,
               "violations": check.violations, "max_deviation": float(np.max(dev)),
               "x_past_range": float(max(x_lo - np.min(samples.pos[:, 0]),
                                         np.max(samples.pos[:, 0]) - x_hi, 0.0))}
        if corners is not None:
            feeds = corner_feeds(path, result.profile, corners)
            rec["corner_feeds"] = feeds
            rec["min_corner_feed"] = min(feeds)
        out[method] = rec
    return out


def table(name: str, rows: list[dict]) -> None:
    print(f"\n{name}")
    print(f"  {'fit':<12} {'tol':>5} {'pieces':>7} {'heur s':>8} {'max dev':>10} "
          f"{'X past':>8} {'corner v':>9} {'ok':>3}  lp")
    for r in rows:
        h = r["heuristic"]
        lp = r.get("lp")
        lp_txt = "" if lp is None else (f"{lp['time_s']:.3f} s ok={lp['checker_ok']}"
                                        if "time_s" in lp else "FAIL " + lp["failed"][:60])
        if "time_s" not in h:
            print(f"  {r['fit']:<12} {r['tolerance']:>5g} {r['pieces']:>7} FAIL {h['failed']}")
            continue
        corner = f"{h['min_corner_feed']:9.2f}" if "min_corner_feed" in h else " " * 9
        print(f"  {r['fit']:<12} {r['tolerance']:>5g} {r['pieces']:>7} {h['time_s']:8.3f} "
              f"{h['max_deviation']:10.4g} {h['x_past_range']:8.3g} {corner} "
              f"{'yes' if h['checker_ok'] else 'NO':>3}  {lp_txt}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="the zig-zag and one CAM program")
    ap.add_argument("--no-lp", action="store_true", help="heuristic only")
    ap.add_argument("--corpus", action="store_true",
                    help="also every points path of the fast corpus (heuristic only: the LP "
                         "takes minutes on some of them)")
    ap.add_argument("--out", default=str(RESULTS / "fidelity.json"))
    args = ap.parse_args()
    use_lp = not args.no_lp
    report: dict = {"fits": [f[0] for f in FITS], "paths": {}}

    config = default_config()
    out = FsPath(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)

    def record(name: str, rows: list[dict], title: str) -> None:
        report["paths"][name] = rows
        table(title, rows)
        out.write_text(json.dumps(report, indent=1))  # after every path: partial runs count

    record("zigzag", [run_fit(ZIGZAG, config, *f, use_lp, ZIGZAG[1:-1]) for f in FITS],
           "zigzag (default winder, X mm / C deg)")

    from bench.corpus import load_corpus

    cams = [p for p in load_corpus("all", skip_long=True) if p.name in CAM_PATHS]
    if args.quick:
        cams = cams[:1]
    extra = []
    if args.corpus:
        extra = [p for p in load_corpus("fast", skip_long=True)
                 if p.segments[0].kind == "points" and p.name not in CAM_PATHS]
    for p in [*cams, *extra]:
        pts = job_points(p.segments)
        lp = use_lp and p.name in CAM_PATHS
        record(p.name, [run_fit(pts, p.config, *f, lp, None) for f in FITS],
               f"{p.name} ({p.family}, {len(pts)} points)")
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
