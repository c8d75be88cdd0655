"""The heuristic's C1-knot share (`path_limits.BudgetShares.c1_knot`) swept on C1 paths:
the measurement its default is taken from.

At a C1 knot (a pchip fit) the axis acceleration steps by |jump of x_ss| v^2, which the
checker's third difference sees as a jerk of up to 3/4 of that step over dt. The
heuristic caps the feed at each knot at sqrt(share jmax dt / |jump|) and leaves the
cells beside it 1 - 3/4 share of jmax for the rest: a larger share passes the knot
faster but brakes and rises around it under less jerk. The windowed LP takes the whole
share (its knot cap is sqrt(jmax dt / |jump|), `lp.knots`).

Paths: the corpus's two C1 paths and ten generated apart from it (helical tubes of
other radii, angles and point spacings, random walks in 2 and 3 axes at 0.5-20 mm
spacing under limits of three scales, circles of R 5 and 30 mm, the Fourier and wander
paths of the heuristic tests), each planned whole at the limits x 0.98 and judged by the
independent checker at the full limits.

    .venv/bin/python bench/c1_knot_share.py [--out bench/results/c1_knot_share.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace

import numpy as np
from scipy.ndimage import gaussian_filter1d

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
sys.path.insert(0, os.path.join(HERE, ".."))

from bench.corpus import load_corpus  # noqa: E402
from heuristic_paths import LIMITS, SCALE, fourier_points, helical_tube, wandering_points  # noqa: E402
from lookahead.checker import LimitChecker  # noqa: E402
from lookahead.geometry.spline_path import fit_points  # noqa: E402
from lookahead.limits import AxisLimits  # noqa: E402
from lookahead.planning.base import PathState, PlanRequest  # noqa: E402
from lookahead.planning.heuristic import HeuristicPlanner  # noqa: E402
from lookahead.planning.heuristic.planner import LAYOUTS  # noqa: E402
from lookahead.sampling import sample_profile, sample_times  # noqa: E402

SHARES = (0.25, 0.5, 0.75, 1.0)
MARGIN = 0.98
CHUNK = 20_000


def random_walk(seed: int, n: int, dim: int, spacing: float) -> np.ndarray:
    """n points `spacing` apart along a smoothed random walk in `dim` axes."""
    rng = np.random.default_rng(seed)
    steps = gaussian_filter1d(rng.normal(size=(n, dim)), 4, axis=0)
    steps /= np.linalg.norm(steps, axis=1)[:, None]
    return np.cumsum(steps * spacing, axis=0)


def circle(radius: float, spacing: float, turns: int = 2) -> np.ndarray:
    n = int(2 * np.pi * radius * turns / spacing)
    th = np.linspace(0.0, 2 * np.pi * turns, n)
    return np.column_stack([radius * np.cos(th), radius * np.sin(th)])


def _same(naxes: int, v: float, a: float, j: float) -> AxisLimits:
    return AxisLimits(np.full(naxes, v), np.full(naxes, a), np.full(naxes, j))


def cases() -> list[tuple[str, object, AxisLimits, float]]:
    """(name, path, full limits, dt) of every C1 path of the sweep."""
    out = []
    for p in load_corpus("all", skip_long=True):
        path = p.path()
        if path.continuity() < 2:
            m = p.config.machine
            out.append((p.name, path, m.limits, m.dt))
    pchip = [
        ("tube-800-R60-70", fit_points(helical_tube(800, 60, 70), SCALE, "pchip"), LIMITS),
        ("tube-300-R25-20-0p5mm",
         fit_points(helical_tube(300, 25, 20, spacing=0.5), SCALE, "pchip"), LIMITS),
        ("tube-2000-R400-80-10mm",
         fit_points(helical_tube(2000, 400, 80, spacing=10.0), SCALE, "pchip"), LIMITS),
        ("wander-7", fit_points(wandering_points(7), SCALE, "pchip"), LIMITS),
        ("fourier-3000", fit_points(fourier_points(), SCALE, "pchip"), LIMITS),
        ("rand2-0p5mm", fit_points(random_walk(1, 800, 2, 0.5), np.ones(2), "pchip"),
         _same(2, 150.0, 1500.0, 20000.0)),
        ("rand3-5mm", fit_points(random_walk(2, 600, 3, 5.0), np.ones(3), "pchip"),
         _same(3, 500.0, 5000.0, 50000.0)),
        ("rand2-20mm-slow", fit_points(random_walk(3, 200, 2, 20.0), np.ones(2), "pchip"),
         _same(2, 50.0, 200.0, 2000.0)),
        ("circle-R30-1mm", fit_points(circle(30.0, 1.0), np.ones(2), "pchip"),
         _same(2, 200.0, 2000.0, 40000.0)),
        ("circle-R5-0p2mm-fast", fit_points(circle(5.0, 0.2), np.ones(2), "pchip"),
         _same(2, 1000.0, 20000.0, 1e6)),
    ]
    out += [(f"gen-{name}-pchip", path, lim, 0.001) for name, path, lim in pchip]
    return out


def planner_with_share(share: float) -> HeuristicPlanner:
    """The default heuristic planner with every layout's C1-knot share set to `share`."""
    layouts = tuple(replace(L, shares=replace(L.shares, c1_knot=share)) for L in LAYOUTS)
    return HeuristicPlanner(margin=1.0, layouts=layouts, shares=replace(
        layouts[0].shares, c1_knot=share))


def run(path, limits: AxisLimits, dt: float, share: float) -> dict:
    request = PlanRequest(path, limits.scaled(MARGIN), PathState(0.0), path.length, dt=dt)
    t0 = time.perf_counter()
    result = planner_with_share(share).plan(request)
    compute = time.perf_counter() - t0
    times = sample_times(result.profile.duration, dt)
    checker = LimitChecker(limits, dt)
    for a in range(0, len(times), CHUNK):
        checker.feed(sample_profile(path, result.profile, times[a:a + CHUNK]).pos)
    rep = checker.report()
    return {"winding_s": result.profile.duration, "violations": rep.violations,
            "peak_jerk": max(rep.peak_fraction["j"]), "compute_s": compute}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(HERE, "results", "c1_knot_share.json"))
    args = ap.parse_args(argv)
    rows: dict[str, dict] = {}
    for name, path, limits, dt in cases():
        rows[name] = {}
        for share in SHARES:
            rows[name][str(share)] = got = run(path, limits, dt, share)
            print(f"{name:36s} share {share:4}: {got['winding_s']:9.3f} s, "
                  f"{got['violations']} violations, peak jerk {got['peak_jerk']:.3f}",
                  flush=True)
    summary = {}
    for share in SHARES:
        regret = [rows[n][str(share)]["winding_s"]
                  / min(r["winding_s"] for r in rows[n].values()) for n in rows]
        summary[str(share)] = {
            "violations": sum(rows[n][str(share)]["violations"] for n in rows),
            "worst_to_best_share": max(regret),
            "geomean_to_best_share": float(np.exp(np.mean(np.log(regret))))}
        print(f"share {share}: {summary[str(share)]}")
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"paths": rows, "summary": summary, "margin": MARGIN}, f, indent=1)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
