"""General CNC paths: smooth random curves in 2..6 axes (limits of very different scales),
near-cusps, sharp tangent corners (B-spline pieces meeting at a corner), a smooth Fourier
path on the winder, very short (< 1 mm) and very long (100k+ points) paths.

Random curves are sums of a few Fourier modes per axis with seeded amplitudes and phases
(`rng_for(name)`), sampled at a fixed parameter step; axis ranges r_i are chosen per path
and the limits scale with them (vmax ~ r/2 per s, amax ~ 10 r, jmax ~ 300 r), so every
axis matters whatever its unit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bench.corpus.base import (
    CorpusPath,
    Piece,
    clamped_knots,
    machine_config,
    piece_segments,
    point_segments,
    resample,
    rng_for,
    winder_config,
)

XYZ_LIMITS = {"vmax": 200.0, "amax": 2000.0, "jmax": 40000.0}
ROTARY_LIMITS = {"vmax": 360.0, "amax": 3600.0, "jmax": 72000.0}


def fourier_curve(rng: np.random.Generator, naxes: int, modes: int, t: np.ndarray,
                  ranges: Sequence[float]) -> np.ndarray:
    """(len(t), naxes): each axis a sum of `modes` sines with 1/k^2 amplitudes, scaled to
    its range r_i (peak-to-peak about r_i)."""
    out = np.zeros((t.size, naxes))
    for i in range(naxes):
        k = np.arange(1, modes + 1)
        amp = rng.normal(size=modes) / k**2
        phase = rng.uniform(0, 2 * np.pi, size=modes)
        freq = k * rng.uniform(0.7, 1.3, size=modes)
        x = np.sum(amp[:, None] * np.sin(2 * np.pi * freq[:, None] * t[None, :]
                                         + phase[:, None]), axis=0)
        x -= x[0]
        span = float(np.ptp(x)) or 1.0
        out[:, i] = x / span * ranges[i]
    return out


def _random_entry(name: str, axes: Sequence[str], units: Sequence[str],
                  ranges: Sequence[float], npoints: int, modes: int, *, metric: str = "norm",
                  rotary_radius: float = 50.0, fit: str = "cubic", chunk: int = 200,
                  fast: bool = False, long: bool = False, note: str = "") -> CorpusPath:
    """A random smooth path of `npoints` points; limits proportional to each axis range
    (linear mm axes) or the rotary defaults (deg axes). metric: 'norm' scales each axis by
    1/range (so every axis contributes to s), 'raw' uses 1 (mm) / pi/180 R (deg)."""
    r = np.asarray(ranges, dtype=float)
    rot = np.array([u == "deg" for u in units])
    vmax = np.where(rot, ROTARY_LIMITS["vmax"], np.maximum(0.5 * r, 1e-3))
    amax = np.where(rot, ROTARY_LIMITS["amax"], 10.0 * r)
    jmax = np.where(rot, ROTARY_LIMITS["jmax"], 300.0 * r)
    # norm: 100 path units per axis range; raw: mm, and deg at `rotary_radius`
    scale = (100.0 / r if metric == "norm"
             else np.where(rot, math.pi / 180.0 * rotary_radius, 1.0))
    cfg = machine_config(axes, units, vmax, amax, jmax, scale, fit=fit)

    def build(job: str) -> list:
        pts = fourier_curve(rng_for(name), len(axes), modes, np.linspace(0.0, 1.0, npoints), r)
        return point_segments(job, axes, pts, chunk, fit=fit)

    desc = (f"random smooth path, {len(axes)} axes {''.join(axes)}, {npoints} points, "
            f"{modes} modes, axis ranges {', '.join(f'{x:g}' for x in r)}, metric {metric}"
            + note)
    return CorpusPath(name, "cnc", cfg, build, notes=desc,
                      params={"kind": "random", "naxes": len(axes), "ranges": list(r),
                              "npoints": npoints, "metric": metric},
                      fast=fast, long=long)


def _xy_config(fit: str = "cubic", **limits: float) -> object:
    lim = {**XYZ_LIMITS, **limits}
    return machine_config(["X", "Y"], ["mm", "mm"], [lim["vmax"]] * 2, [lim["amax"]] * 2,
                          [lim["jmax"]] * 2, fit=fit)


def _points_entry(name: str, cfg, pts_fn, desc: str, params: dict, *, chunk: int = 200,
                  fit: str = "cubic", fast: bool = False, long: bool = False) -> CorpusPath:
    axes = cfg.machine.axes

    def build(job: str) -> list:
        return point_segments(job, axes, pts_fn(), chunk, fit=fit)

    return CorpusPath(name, "cnc", cfg, build, notes=desc, params=params, fast=fast,
                      long=long)


def _pieces_entry(name: str, cfg, pieces_fn, desc: str, params: dict, *,
                  fast: bool = False) -> CorpusPath:
    axes = cfg.machine.axes

    def build(job: str) -> list:
        return piece_segments(job, axes, pieces_fn())

    return CorpusPath(name, "cnc", cfg, build, notes=desc, params=params, fast=fast)


def corner_pieces(name: str, naxes: int, corners: int, size: float, degree: int = 3,
                  ctrl_per_piece: int = 6) -> list[Piece]:
    """`corners` + 1 B-spline pieces, each from the previous piece's end to a random
    point, with random inner control points: they meet at tangent corners of random
    angle (one near-tangent, one near-reversal among them)."""
    rng = rng_for(name)
    pieces, start = [], np.zeros(naxes)
    prev_dir = None
    for j in range(corners + 1):
        d = rng.normal(size=naxes)
        d /= np.linalg.norm(d)
        if prev_dir is not None and j == 1:
            d = prev_dir + 0.02 * rng.normal(size=naxes)  # near-tangent corner (~1 deg)
            d /= np.linalg.norm(d)
        if prev_dir is not None and j == 2:
            d = -prev_dir + 0.05 * rng.normal(size=naxes)  # near-reversal (~177 deg)
            d /= np.linalg.norm(d)
        end = start + size * rng.uniform(0.5, 1.5) * d
        inner = (start + (end - start) * np.linspace(0, 1, ctrl_per_piece)[1:-1, None]
                 + 0.25 * size * rng.normal(size=(ctrl_per_piece - 2, naxes)))
        # the first inner control point on the chord direction so the piece leaves along d
        inner[0] = start + (end - start) / (ctrl_per_piece - 1)
        ctrl = np.vstack([start, inner, end])
        pieces.append(Piece(degree, clamped_knots(len(ctrl), degree), ctrl))
        prev_dir = (ctrl[-1] - ctrl[-2]) / np.linalg.norm(ctrl[-1] - ctrl[-2])
        start = end
    return pieces


def polyline_pieces(name: str, n: int, size: float) -> list[Piece]:
    """Degree-1 pieces (straight moves) of a random polygon: a stop at every corner."""
    rng = rng_for(name)
    pts = np.cumsum(np.vstack([np.zeros(2), size * rng.normal(size=(n, 2))]), axis=0)
    return [Piece(1, np.array([0.0, 0.0, 1.0, 1.0]), pts[i:i + 2]) for i in range(n)]


def jog_walk(name: str, n: int, step: float) -> np.ndarray:
    """n XY points (mm) of a random walk with normal steps of `step` mm per axis: a
    quarter of its points reverse both axes, the cusps of a pchip fit through them."""
    rng = rng_for(name)
    return np.cumsum(np.vstack([np.zeros(2), step * rng.normal(size=(n - 1, 2))]), axis=0)


def cycloid_points(a: float, scale: float, loops: float, spacing: float) -> np.ndarray:
    """A prolate/curtate cycloid x = t - a sin t, y = 1 - a cos t (mm after `scale`):
    a -> 1 makes cusps (a = 1 exactly: true cusps, the tangent reverses)."""
    def curve(u: np.ndarray) -> np.ndarray:
        t = 2 * np.pi * loops * u
        return scale * np.column_stack([t - a * np.sin(t), 1 - a * np.cos(t)])

    return resample(curve, spacing, np.ones(2), dense=200_000)


def near_cusp_piece() -> list[Piece]:
    """One cubic B-spline whose control polygon folds back on itself: the curve slows to
    a near-stop and turns ~180 deg within ~0.01 mm (a near-cusp)."""
    ctrl = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [25.0, 0.02], [20.0, 0.04],
                     [10.0, 0.5], [0.0, 2.0]])
    return [Piece(3, clamped_knots(len(ctrl), 3), ctrl)]


def fourier_winder_points(name: str, n: int) -> np.ndarray:
    """[X mm, C deg], n points: X a smooth Fourier sum (span ~400 mm), C a steady
    advance (~20 turns) plus Fourier terms that reverse it briefly (C mostly increasing)."""
    rng = rng_for(name)
    t = np.linspace(0.0, 1.0, n)
    x = fourier_curve(rng, 1, 8, t, [400.0])[:, 0]
    wobble = fourier_curve(rng, 1, 6, t, [1.0])[:, 0]
    c = 7200.0 * t + 2500.0 * wobble  # C reverses on ~11 % of the steps
    return np.column_stack([x, c])


def curvature_walk(name: str, n: int, spacing: float) -> np.ndarray:
    """n XY points `spacing` mm apart whose heading turns with a smooth random curvature
    kappa(s) (1/mm): a sum of 12 sines of wavelengths 20..800 mm, scaled to |kappa| <= 0.2;
    the heading and position are integrated by the midpoint rule."""
    rng = rng_for(name)
    s = np.arange(n) * spacing
    wl = np.exp(rng.uniform(np.log(20.0), np.log(800.0), size=12))
    amp = rng.normal(size=12) * np.sqrt(wl / 800.0)
    phase = rng.uniform(0, 2 * np.pi, size=12)
    kappa = np.zeros(n)
    for w, a, p in zip(wl, amp, phase, strict=True):
        kappa += a * np.sin(2 * np.pi * s / w + p)
    kappa *= 0.2 / np.max(np.abs(kappa))
    heading = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * spacing)])
    mid = 0.5 * (heading[1:] + heading[:-1])
    steps = spacing * np.column_stack([np.cos(mid), np.sin(mid)])
    return np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])


def spiral_points(turns: float, pitch: float, spacing: float) -> np.ndarray:
    """An Archimedean spiral r = pitch theta / 2 pi from the centre out (curvature
    unbounded at the start)."""
    def curve(u: np.ndarray) -> np.ndarray:
        th = 2 * np.pi * turns * u
        r = pitch * th / (2 * np.pi) + 0.2
        return np.column_stack([r * np.cos(th), r * np.sin(th)])

    return resample(curve, spacing, np.ones(2), dense=400_000)


def corpus() -> list[CorpusPath]:
    out: list[CorpusPath] = [
        _random_entry("c-rand2-xy-500pts", ["X", "Y"], ["mm", "mm"], [120, 80], 500, 6,
                      metric="raw", fast=True),
        _random_entry("c-rand3-xyz-2000pts", ["X", "Y", "Z"], ["mm"] * 3, [300, 200, 50],
                      2000, 10, metric="raw"),
        _random_entry("c-rand4-xyza-1500pts", ["X", "Y", "Z", "A"], ["mm", "mm", "mm", "deg"],
                      [200, 150, 40, 270], 1500, 8, metric="raw"),
        _random_entry("c-rand5-xyzac-1200pts", ["X", "Y", "Z", "A", "C"],
                      ["mm", "mm", "mm", "deg", "deg"], [250, 250, 80, 90, 720], 1200, 8,
                      metric="raw", rotary_radius=30.0),
        _random_entry("c-rand6-scales-1e-2-1e4-norm", ["U", "V", "W", "X", "Y", "Z"],
                      ["mm"] * 6, [1e-2, 1e-1, 1.0, 1e2, 1e3, 1e4], 800, 6, metric="norm",
                      fast=True, note=" (limits scale with each axis: 5e-3 .. 5e3 mm/s)"),
        _random_entry("c-rand6-scales-1e-2-1e4-raw", ["U", "V", "W", "X", "Y", "Z"],
                      ["mm"] * 6, [1e-2, 1e-1, 1.0, 1e2, 1e3, 1e4], 800, 6, metric="raw",
                      note=" (raw mm metric: the small axes barely move s)"),
        _random_entry("c-rand3-xyz-pchip-1000pts", ["X", "Y", "Z"], ["mm"] * 3,
                      [100, 100, 100], 1000, 12, metric="raw", fit="pchip"),
    ]
    xy = _xy_config()
    out.append(_points_entry(
        "c-long-curvature-xy-110kpts", xy,
        lambda: curvature_walk("c-long-curvature-xy-110kpts", 110_000, 0.5),
        "a long XY job: 110k points 0.5 mm apart along a smooth random curvature "
        "(|kappa| <= 0.2 /mm, wavelengths 20..800 mm)",
        {"kind": "random", "npoints": 110_000, "spacing": 0.5}, chunk=500, long=True))
    winder = winder_config(None)
    out.append(_points_entry(
        "c-fourier-xc-3000pts", winder,
        lambda: fourier_winder_points("c-fourier-xc-3000pts", 3000),
        "smooth Fourier path on the default winder, 3000 points, C mostly increasing "
        "(issue 13)", {"kind": "fourier", "npoints": 3000}, fast=True))
    out.append(_points_entry(
        "c-cycloid-near-cusp-a0p995", xy, lambda: cycloid_points(0.995, 10.0, 3, 0.1),
        "prolate cycloid a = 0.995 (near-cusps), 3 loops, scale 10 mm, 0.1 mm points",
        {"kind": "near-cusp", "a": 0.995, "spacing": 0.1}, fast=True))
    out.append(_points_entry(
        "c-cycloid-cusp-a1", xy, lambda: cycloid_points(1.0, 10.0, 2, 0.2),
        "cycloid a = 1 (true cusps: the tangent reverses), 2 loops, 0.2 mm points",
        {"kind": "cusp", "a": 1.0, "spacing": 0.2}))
    out.append(_pieces_entry(
        "c-near-cusp-bspline", xy, near_cusp_piece,
        "one cubic B-spline folding back within 0.02 mm (near-cusp)", {"kind": "near-cusp"}))
    out.append(_pieces_entry(
        "c-corners-bspline-2d", xy, lambda: corner_pieces("c-corners-bspline-2d", 2, 6, 40.0),
        "7 cubic B-spline pieces meeting at tangent corners (one ~1 deg, one ~177 deg)",
        {"kind": "corners", "pieces": 7}, fast=True))
    xyz = machine_config(["X", "Y", "Z"], ["mm"] * 3, [200.0] * 3, [2000.0] * 3,
                         [40000.0] * 3)
    out.append(_pieces_entry(
        "c-corners-bspline-3d-quintic", xyz,
        lambda: corner_pieces("c-corners-bspline-3d-quintic", 3, 10, 25.0, degree=5,
                              ctrl_per_piece=8),
        "11 quintic B-spline pieces in XYZ meeting at tangent corners",
        {"kind": "corners", "pieces": 11}))
    out.append(_pieces_entry(
        "c-polyline-deg1-30", xy, lambda: polyline_pieces("c-polyline-deg1-30", 30, 8.0),
        "30 straight moves (degree-1 pieces): a stop at every corner",
        {"kind": "polyline", "pieces": 30}))
    out.append(_points_entry(
        "c-walk-xy-pchip-cusps-60pts", _xy_config("pchip"),
        lambda: jog_walk("c-walk-xy-pchip-cusps-60pts", 60, 8.0),
        "a random walk of 60 XY points (steps ~8 mm) fitted pchip: where both axes reverse "
        "at a point the fit's tangent vanishes (a cusp, a stop) and elsewhere the knots are "
        "C1", {"kind": "cusp", "npoints": 60, "fit": "pchip"}, fit="pchip"))
    out.append(_points_entry(
        "c-spiral-xy-0p2mm", xy, lambda: spiral_points(12, 4.0, 0.2),
        "Archimedean spiral from the centre, 12 turns, pitch 4 mm, 0.2 mm points",
        {"kind": "spiral", "spacing": 0.2}))
    # very short paths (< 1 mm)
    out.append(_points_entry(
        "c-short-xy-0p5mm", xy,
        lambda: np.column_stack([np.linspace(0, 0.4, 6), 0.3 * np.linspace(0, 1, 6) ** 2]),
        "6 points over ~0.5 mm (XY)", {"kind": "short", "length_mm": 0.5}, fast=True))
    out.append(_pieces_entry(
        "c-short-bspline-0p05mm", xy,
        lambda: [Piece(3, clamped_knots(4, 3),
                       np.array([[0, 0], [0.02, 0.0], [0.03, 0.01], [0.04, 0.03]]))],
        "one cubic B-spline of ~0.05 mm", {"kind": "short", "length_mm": 0.05}))
    out.append(_points_entry(
        "c-short-winder-0p8mm", winder,
        lambda: np.column_stack([np.linspace(0, 0.5, 8), np.linspace(0, 0.35, 8)]),
        "8 points, ~0.8 mm of fibre on the default winder (X 0.5 mm, C 0.35 deg)",
        {"kind": "short", "length_mm": 0.8}))
    return out
