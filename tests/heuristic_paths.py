"""Test paths for the heuristic planner (tests and bench/heuristic_bench.py), built here
independently of the project's presets until the corpus exists.

Every builder returns a `Case`: a name, the fitted path, the machine limits and sample time,
and optionally a feed cap. Units: X mm, C deg (path_scale of the winder) unless stated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lookahead.config import default_config
from lookahead.geometry.base import Path
from lookahead.geometry.spline_path import fit_points
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedCap

MACHINE = default_config().machine
DT = MACHINE.dt
SCALE = np.asarray(MACHINE.path_scale)
LIMITS = MACHINE.limits


def random_polyline(angles_deg: list[float], signs: list[bool], lengths: list[float],
                    scale: np.ndarray) -> np.ndarray:
    """2-axis points whose metric polyline turns by the given angles (axis units; scale:
    the path scale, axis units to path units): left where signs[i], else right."""
    heading = 0.0
    pts = [np.zeros(2)]
    for i, length in enumerate(lengths):
        if i:
            turn = math.radians(angles_deg[i - 1])
            heading += turn if signs[i - 1] else -turn
        step = length * np.array([math.cos(heading), math.sin(heading)])
        pts.append(pts[-1] + step / scale)
    return np.array(pts)


@dataclass(frozen=True)
class Case:
    name: str
    path: Path
    limits: AxisLimits
    dt: float = DT
    feed_cap: FeedCap | None = None


def helical_tube(length: float, radius: float, alpha_deg: float, spacing: float = 2.0,
                 dwell_deg: float = 200.0, circuits: int = 1) -> np.ndarray:
    """Points [X mm, C deg] of helical strokes 0 -> L -> 0 joined by sine-eased turnarounds
    (X velocity per C turn falls as cos over the dwell: X = L + k d sin(pi tau) / pi)."""
    k = radius / np.tan(np.radians(alpha_deg))  # mm of X per rad of C
    stroke = length / k
    dwell = np.radians(dwell_deg)
    n_stroke = int(np.ceil(length / np.cos(np.radians(alpha_deg)) / spacing))
    n_turn = int(np.ceil(np.hypot(k * dwell * 2 / np.pi, radius * dwell) / spacing))
    ts, tt = np.arange(n_stroke) / n_stroke, np.arange(n_turn) / n_turn
    xs, cs, c0 = [], [], 0.0
    for _ in range(circuits):
        for sign, x0 in ((1.0, 0.0), (-1.0, length)):
            xs += [x0 + sign * length * ts, x0 + sign * length
                   + sign * k * dwell * np.sin(np.pi * tt) / np.pi]
            cs += [c0 + stroke * ts, c0 + stroke + dwell * tt]
            c0 += stroke + dwell
    x = np.concatenate([*xs, [0.0]])
    c = np.concatenate([*cs, [c0]])
    return np.column_stack([x, np.degrees(c)])


def fourier_points(n: int = 3000, seed: int = 3) -> np.ndarray:
    """A smooth path of n points: X a sum of random sines, C mostly increasing."""
    rng = np.random.default_rng(seed)
    tau = np.linspace(0.0, 1.0, n)
    x = np.zeros(n)
    for _ in range(6):
        x += rng.uniform(20, 150) * np.sin(2 * np.pi * rng.integers(1, 12) * tau
                                           + rng.uniform(0, 2 * np.pi))
    c = 3000.0 * tau + 40.0 * np.sin(2 * np.pi * 3 * tau + rng.uniform(0, 6))
    return np.column_stack([x, c])


def issue13_fourier_points(n: int = 3000, seed: int = 0) -> np.ndarray:
    """Issue 13's smooth Fourier path: X a sum of random sines (mm), C increasing plus
    small sines (deg); with seed 0, C reverses near s = 756 mm (a near-cusp)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n)
    x = sum(rng.uniform(20, 150) * np.sin(2 * np.pi * (f * t + rng.uniform()))
            for f in rng.integers(1, 8, 4))
    c = 3600.0 * t + sum(rng.uniform(5, 40) * np.sin(2 * np.pi * (f * t + rng.uniform()))
                         for f in rng.integers(2, 15, 3))
    return np.column_stack([x, c])


def wiggly_points(n: int = 400, seed: int = 5) -> np.ndarray:
    """A wiggly 2-axis (mm, mm) curve: a random walk smoothed by a few passes."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(n, 2)) * 3.0 + np.array([2.0, 0.5])
    pts = np.cumsum(steps, axis=0)
    for _ in range(3):
        pts[1:-1] = 0.25 * pts[:-2] + 0.5 * pts[1:-1] + 0.25 * pts[2:]
    return pts


def wandering_points(seed: int, npts: int = 12) -> np.ndarray:
    """Random points [X mm, C deg] whose X often reverses with a small C step."""
    rng = np.random.default_rng(seed)
    back = rng.random(npts) < 0.5
    sign = np.where(np.arange(npts) % 2 == 0, 1.0, -1.0)
    dx = np.where(back, sign * rng.uniform(3.0, 30.0, npts), rng.normal(size=npts) * 15.0)
    dc = np.where(back, rng.uniform(0.1, 2.0, npts), rng.normal(size=npts) * 30.0)
    return np.cumsum(np.vstack([[0.0, 0.0], np.c_[dx, dc]]), axis=0)


def random_walk(seed: int, naxes: int, npoints: int, log_step: float, log_spread: float,
                fit: str) -> tuple[Path, AxisLimits]:
    """The path and limits of a case of `bench/fuzz_paths.py` (a random walk of `npoints`
    in `naxes` axes, steps ~10^log_step with each axis scaled by up to 10^|log_spread|,
    fitted by `fit`; limits over decades), which its `--case` replays."""
    from bench.fuzz_paths import build

    built = build((seed, naxes, npoints, log_step, log_spread, fit))
    assert built is not None, "the case makes no path"
    return built


def pchip_cusp() -> tuple[Path, AxisLimits]:
    """An XY path (mm) through 7 points fitted pchip, with one cusp: at (25, 10) both
    axes reverse, so the fit's tangent vanishes there (a corner, `Path.corners_s`); its
    other knots are C1. Limits of an ordinary XY table."""
    pts = np.array([[0, 0], [10, 4], [25, 10], [12, 6], [4, 14], [10, 22], [3, 30.0]])
    path = fit_points(pts, np.ones(2), "pchip")
    return path, AxisLimits(np.array([100.0, 150.0]), np.array([1000.0, 2000.0]),
                            np.array([2e4, 3e4]))


def near_zero_cap(path: Path) -> FeedCap:
    """A feed cap with two stretches at a crawl (1 mm at 0.2 mm/s, 10 mm at 2 mm/s: 5 s
    each) and a high rest."""
    L = path.length
    breaks = np.array([0.0, 0.3 * L, 0.3 * L + 1.0, 0.6 * L, 0.6 * L + 10.0, L])
    return FeedCap(breaks, np.array([1e4, 0.2, 1e4, 2.0, 1e4]))


def cases(quick: bool = False) -> list[Case]:
    """The bench's path set (quick: the small ones only)."""
    from lookahead.geometry.winding import preset_points

    out = [
        Case("tube-800-R60-70", fit_points(helical_tube(800, 60, 70), SCALE, "cubic"), LIMITS),
        Case("fourier-3000", fit_points(fourier_points(), SCALE, "cubic"), LIMITS),
        Case("wiggly-mm", fit_points(wiggly_points(), np.ones(2), "cubic"),
             AxisLimits(np.full(2, 150.0), np.full(2, 1500.0), np.full(2, 20000.0))),
        Case("tube-800-pchip", fit_points(helical_tube(800, 60, 70), SCALE, "pchip"), LIMITS),
        Case("wander-7-pchip", fit_points(wandering_points(7), SCALE, "pchip"), LIMITS),
    ]
    for seed in (1, 2, 3):
        out.append(Case(f"wander-{seed}", fit_points(wandering_points(seed), SCALE, "cubic"),
                        LIMITS))
    fourier = fit_points(fourier_points(800, seed=9), SCALE, "cubic")
    out.append(Case("fourier-800-crawl", fourier, LIMITS, feed_cap=near_zero_cap(fourier)))
    if not quick:
        out.insert(0, Case("tube-1450-R100-45",
                           fit_points(helical_tube(1450, 100, 45), SCALE, "cubic"), LIMITS))
        for name in ("tube-1450", "tube-9570"):
            _, pts, _ = preset_points(name)
            out.append(Case(name, fit_points(pts, SCALE, "cubic"), LIMITS))
        out.append(Case("fourier-3000-pchip", fit_points(fourier_points(), SCALE, "pchip"),
                        LIMITS))
    return out
