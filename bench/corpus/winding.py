"""Winding paths in machine axes X (mm, carriage) / C (deg, mandrel, unwrapped), written
independently of `lookahead.geometry.winding` (other turnarounds, mandrels and spacings).

Model (simplified, as a CAM post-processor's output would be): the carriage X sits at the
fibre's contact point, so on a cylinder of radius R at winding angle alpha (from the
mandrel axis) dX = k dC with k = R cot(alpha) mm/rad. A turnaround reverses dX/dC from +k
to -k while C turns the dwell angle D:

- `sine`:  dX/dC = k cos(pi tau) (X overshoots by k D / pi; C2 at the joins in C);
- `cycloid`: dX/dC = k (1 - 2 (tau - sin(2 pi tau) / (2 pi))) (C3 joins; a cosine ease of
  the slope);
- `septic`: dX/dC = k (1 - 2 S7(tau)), S7 the septic smoothstep (C4 joins);
- `dwell`: an abrupt reversal: X holds while C turns D (tangent corners at both ends);
- `overshoot`: the carriage runs past the end by e = 1.6 k D / pi on a sine, so the
  slope jumps by 60 % at the joins (a kink, as a carriage overshoot without blend).

Domes: a hemispherical end of radius R, crossed on a great circle (a geodesic of the
sphere, winding angle alpha at the equator): X = x_end + R cos(alpha) sin t,
C = c0 + atan2(sin t sin(alpha), cos t), t in [0, pi]. Cones: R(x) linear in x, constant
winding angle: dC/dx = tan(alpha) / R(x). Points are spaced `spacing` mm in the path
metric (path_scale of C: pi/180 R_nominal), exactly (`base.resample`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bench.corpus.base import CorpusPath, chain, point_segments, resample, winder_config

Curve = Callable[[np.ndarray], np.ndarray]
TURNS = ("sine", "cycloid", "septic", "dwell", "overshoot")
#: the overshoot turnaround's slope factor at the joins (see the module docstring)
OVERSHOOT_SLOPE = 1.6


def _xc(x: np.ndarray, c_rad: np.ndarray) -> np.ndarray:
    return np.column_stack([x, np.degrees(c_rad)])


def _s7_integral(t: np.ndarray) -> np.ndarray:
    return 7 * t**5 - 14 * t**6 + 10 * t**7 - 2.5 * t**8


def turn_offset(shape: str, tau: np.ndarray) -> np.ndarray:
    """X offset per (k D) over the turnaround, tau in [0, 1] (0 at both ends)."""
    if shape == "sine":
        return np.sin(np.pi * tau) / np.pi
    if shape == "cycloid":
        return tau - tau**2 + (1.0 - np.cos(2 * np.pi * tau)) / (2 * np.pi**2)
    if shape == "septic":
        return tau - 2.0 * _s7_integral(tau)
    if shape == "dwell":
        return np.zeros_like(tau)
    if shape == "overshoot":
        return OVERSHOOT_SLOPE * np.sin(np.pi * tau) / np.pi
    raise ValueError(f"turnaround shape {shape!r} not in {TURNS}")


@dataclass
class Tracer:
    """Builds a winding as consecutive point runs; (x, c) is where the last run ended
    (mm, rad). path_scale: of the machine (C in deg)."""

    path_scale: np.ndarray
    x: float = 0.0
    c: float = 0.0

    def __post_init__(self) -> None:
        self.runs: list[np.ndarray] = []

    def add(self, curve: Curve, spacing: float) -> None:
        pts = resample(curve, spacing, self.path_scale)
        self.runs.append(pts)
        self.x, self.c = float(pts[-1, 0]), math.radians(float(pts[-1, 1]))

    def stroke(self, x_to: float, k: float, spacing: float) -> None:
        """Constant angle on a cylinder: dX = k dC (k mm/rad), C increasing."""
        x0, c0, dc = self.x, self.c, abs(x_to - self.x) / k
        self.add(lambda t: _xc(x0 + (x_to - x0) * t, c0 + dc * t), spacing)

    def turn(self, shape: str, k: float, dwell_rad: float, direction: int,
             spacing: float) -> None:
        """Turnaround at the current end; direction +1 when X was increasing."""
        x0, c0 = self.x, self.c

        def curve(t: np.ndarray) -> np.ndarray:
            return _xc(x0 + direction * k * dwell_rad * turn_offset(shape, t), c0 + dwell_rad * t)

        self.add(curve, spacing)

    def dome(self, radius: float, alpha_deg: float, direction: int, spacing: float) -> None:
        """A great circle over a hemispherical end (C turns 180 deg)."""
        x0, c0, a = self.x, self.c, math.radians(alpha_deg)

        def curve(t: np.ndarray) -> np.ndarray:
            th = np.pi * t
            return _xc(x0 + direction * radius * math.cos(a) * np.sin(th),
                       c0 + np.arctan2(np.sin(th) * math.sin(a), np.cos(th)))

        self.add(curve, spacing)

    def cone_stroke(self, x_to: float, r_of_x: Callable[[np.ndarray], np.ndarray],
                    alpha_deg: float, spacing: float) -> None:
        """Constant angle on a surface of revolution of radius r(x): dC/dx = tan a / r."""
        x0, c0, ta = self.x, self.c, math.tan(math.radians(alpha_deg))
        xs = np.linspace(x0, x_to, 4001)
        dc = np.concatenate([[0.0], np.cumsum(0.5 * (1 / r_of_x(xs[1:]) + 1 / r_of_x(xs[:-1]))
                                              * np.abs(np.diff(xs)))]) * ta

        def curve(t: np.ndarray) -> np.ndarray:
            x = x0 + (x_to - x0) * t
            return _xc(x, c0 + np.interp(t, np.linspace(0, 1, xs.size), dc))

        self.add(curve, spacing)

    def points(self) -> np.ndarray:
        return chain(self.runs)


def helical(tr: Tracer, length: float, radius: float, alpha_deg: float, strokes: int,
            shape: str, dwell_deg: float, spacing: float,
            turn_spacing: float | None = None) -> None:
    """`strokes` constant-angle strokes over [0, length] with turnarounds between them
    (and none after the last), starting at the tracer's X (0 or length)."""
    k = radius / math.tan(math.radians(alpha_deg))
    dwell = math.radians(dwell_deg)
    if shape == "overshoot":  # dwell_deg is read as the overshoot e (mm)
        dwell = math.pi * dwell_deg / (OVERSHOOT_SLOPE * k)
    for i in range(strokes):
        forward = tr.x < length / 2
        tr.stroke(length if forward else 0.0, k, spacing)
        if i < strokes - 1:
            tr.turn(shape, k, dwell, 1 if forward else -1, turn_spacing or spacing)


def domed(tr: Tracer, length: float, radius: float, alpha_deg: float, strokes: int,
          spacing: float) -> None:
    """A vessel: cylinder [0, length] with hemispherical domes, crossed on great circles."""
    k = radius / math.tan(math.radians(alpha_deg))
    for i in range(strokes):
        forward = tr.x < length / 2
        tr.stroke(length if forward else 0.0, k, spacing)
        if i < strokes - 1:
            tr.dome(radius, alpha_deg, 1 if forward else -1, spacing)


def cone(tr: Tracer, length: float, r0: float, r1: float, alpha_deg: float, strokes: int,
         shape: str, dwell_deg: float, spacing: float) -> None:
    """A frustum, radius r0 at X = 0 to r1 at X = length, constant winding angle;
    turnarounds use the local slope k = r cot(alpha)."""

    def r_of_x(x: np.ndarray) -> np.ndarray:
        return r0 + (r1 - r0) * np.clip(np.asarray(x) / length, 0.0, 1.0)

    cot = 1.0 / math.tan(math.radians(alpha_deg))
    for i in range(strokes):
        forward = tr.x < length / 2
        tr.cone_stroke(length if forward else 0.0, r_of_x, alpha_deg, spacing)
        if i < strokes - 1:
            k = float(r_of_x(np.array(tr.x))) * cot
            tr.turn(shape, k, math.radians(dwell_deg), 1 if forward else -1, spacing)


def hoops(tr: Tracer, length: float, band: float, passes: int, spacing: float) -> None:
    """Hoop passes over [0, length], reversing with a half-turn sine turnaround."""
    k = band / (2 * math.pi)
    for i in range(passes):
        forward = tr.x < length / 2
        tr.stroke(length if forward else 0.0, k, spacing)
        if i < passes - 1:
            tr.turn("sine", k, math.pi, 1 if forward else -1, spacing)


# --- the corpus entries -----------------------------------------------------------------


def _entry(name: str, cfg_radius: float | None, make: Callable[[Tracer], None], notes: str,
           params: dict, fast: bool = False, long: bool = False, chunk: int = 200,
           big: bool = False, fit: str = "cubic") -> CorpusPath:
    cfg = winder_config(cfg_radius, big=big, fit=fit)

    def build(job: str) -> list:
        tr = Tracer(np.asarray(cfg.machine.path_scale))
        make(tr)
        return point_segments(job, cfg.machine.axes, tr.points(), chunk, fit=fit)

    return CorpusPath(name, "winding", cfg, build, notes=notes, params=params, fast=fast,
                      long=long)


def corpus() -> list[CorpusPath]:
    """The winding family (see the module docstring for the geometry)."""
    out: list[CorpusPath] = []

    def hel(name, length, radius, alpha, strokes, shape, dwell, spacing, *, cfg_r="R",
            fast=False, long=False, chunk=200, big=False, fit="cubic", turn_spacing=None,
            note=""):
        cfg_radius = radius if cfg_r == "R" else cfg_r
        params = {"kind": "helical", "length": length, "radius": radius, "alpha_deg": alpha,
                  "strokes": strokes, "turn": shape, "dwell_deg": dwell, "spacing": spacing,
                  "turn_spacing": turn_spacing or spacing}
        desc = (f"helical L {length:g} R {radius:g} mm, {alpha:g} deg, {strokes} strokes, "
                f"{shape} turnarounds ({'e' if shape == 'overshoot' else 'dwell'} {dwell:g}), "
                f"{spacing:g} mm points" + (f", turnarounds {turn_spacing:g} mm"
                                            if turn_spacing else "") + note)
        out.append(_entry(name, cfg_radius, lambda tr: helical(
            tr, length, radius, alpha, strokes, shape, dwell, spacing, turn_spacing),
            desc, params, fast=fast, long=long, chunk=chunk, big=big, fit=fit))

    # the examples (default configuration: path_scale of R = 100 mm)
    hel("w-issue-tube1450-R100-a45-sine-2mm", 1450, 100, 45, 2, "sine", 180, 2.0, cfg_r=None,
        fast=True, note=" (issue 13; default configuration)")
    hel("w-issue-tube800-R60-a70-3pass", 800, 60, 70, 3, "sine", 180, 2.0, cfg_r=None,
        note=" (issue 13; default configuration, C scaled as R = 100)")
    hel("w-issue-tube9570-R150-a55-5mm", 9570, 150, 55, 2, "sine", 180, 5.0, cfg_r=None,
        note=" (issue 13; default configuration, C scaled as R = 100)")
    # cylinders: every turnaround shape, R 25..500, alpha 10..85, spacing 0.2..20
    hel("w-hel-R25-a30-cycloid-0p2mm", 120, 25, 30, 2, "cycloid", 180, 0.2)
    hel("w-hel-R40-a60-septic-1mm", 400, 40, 60, 4, "septic", 270, 1.0)
    hel("w-hel-R50-a45-sine-2mm-short", 300, 50, 45, 2, "sine", 180, 2.0, fast=True)
    hel("w-hel-R100-a45-dwell-2mm", 800, 100, 45, 3, "dwell", 180, 2.0)
    hel("w-hel-R60-a10-dwell-1mm", 500, 60, 10, 2, "dwell", 360, 1.0)
    hel("w-hel-R150-a20-overshoot-5mm", 1500, 150, 20, 3, "overshoot", 120, 5.0)
    hel("w-hel-R80-a35-overshoot-1mm", 300, 80, 35, 2, "overshoot", 40, 1.0)
    hel("w-hel-R250-a55-sine-10mm", 2500, 250, 55, 3, "sine", 180, 10.0, big=True)
    hel("w-hel-R500-a80-cycloid-20mm", 3000, 500, 80, 2, "cycloid", 90, 20.0, big=True)
    hel("w-hel-R100-a85-septic-2mm", 300, 100, 85, 2, "septic", 90, 2.0)
    hel("w-hel-R120-a45-sine-mixed-10mm-0p5mm", 1200, 120, 45, 2, "sine", 180, 10.0,
        turn_spacing=0.5)
    hel("w-hel-R100-a45-sine-2mm-pchip", 800, 100, 45, 2, "sine", 180, 2.0, fit="pchip")
    hel("w-long-layer-R100-a45-sine-2mm", 1450, 100, 45, 88, "sine", 180, 2.0, long=True,
        chunk=500, note=" (a long job: 44 circuits)")

    def ent(name, cfg_radius, make, desc, params, **kw):
        out.append(_entry(name, cfg_radius, make, desc, params, **kw))

    ent("w-hoop-R40-band8-2mm", 40,
        lambda tr: hoops(tr, 40, 8, 2, 2.0),
        "hoop layer L 40 R 40 mm, band 8 mm, 2 passes (sine reversal), 2 mm points",
        {"kind": "hoop", "length": 40, "radius": 40, "band": 8, "spacing": 2.0,
         "alpha_deg": math.degrees(math.atan(2 * math.pi * 40 / 8))}, fast=True)
    ent("w-hoop-R300-band16-8mm", 300,
        lambda tr: hoops(tr, 240, 16, 2, 8.0),
        "hoop layer L 240 R 300 mm, band 16 mm, 2 passes, 8 mm points (big winder)",
        {"kind": "hoop", "length": 240, "radius": 300, "band": 16, "spacing": 8.0,
         "alpha_deg": math.degrees(math.atan(2 * math.pi * 300 / 16))}, big=True)
    ent("w-polar-dome-R100-a8-2mm", 100,
        lambda tr: domed(tr, 300, 100, 8, 4, 2.0),
        "polar layer on a vessel L 300 R 100 mm with hemispherical domes, 8 deg, 4 strokes "
        "(great-circle turnarounds over the poles), 2 mm points",
        {"kind": "polar", "length": 300, "radius": 100, "alpha_deg": 8, "spacing": 2.0})
    ent("w-polar-dome-R30-a5-0p5mm", 30,
        lambda tr: domed(tr, 120, 30, 5, 2, 0.5),
        "polar layer on a vessel L 120 R 30 mm, hemispherical domes, 5 deg, 0.5 mm points",
        {"kind": "polar", "length": 120, "radius": 30, "alpha_deg": 5, "spacing": 0.5},
        fast=True)
    ent("w-dome-R150-a30-3mm", 150,
        lambda tr: domed(tr, 900, 150, 30, 3, 3.0),
        "helical layer on a domed vessel L 900 R 150 mm, 30 deg, 3 strokes, 3 mm points",
        {"kind": "dome", "length": 900, "radius": 150, "alpha_deg": 30, "spacing": 3.0})
    ent("w-cone-R80to40-a35-sine-2mm", 60,
        lambda tr: cone(tr, 600, 80, 40, 35, 3, "sine", 180, 2.0),
        "cone L 600 mm, R 80 -> 40 mm, 35 deg, 3 strokes, sine turnarounds, 2 mm points "
        "(C scaled as R = 60)",
        {"kind": "cone", "length": 600, "radius": 80, "radius_end": 40, "alpha_deg": 35,
         "spacing": 2.0})
    ent("w-cone-R200to120-a50-dwell-4mm", 160,
        lambda tr: cone(tr, 1000, 200, 120, 50, 2, "dwell", 180, 4.0),
        "cone L 1000 mm, R 200 -> 120 mm, 50 deg, abrupt reversal with a 180 deg dwell, "
        "4 mm points (C scaled as R = 160)",
        {"kind": "cone", "length": 1000, "radius": 200, "radius_end": 120, "alpha_deg": 50,
         "spacing": 4.0})

    def layers_a(tr: Tracer) -> None:
        helical(tr, 300, 100, 45, 4, "sine", 180, 2.0)
        hoops(tr, 300, 15, 2, 4.0)
        helical(tr, 300, 100, 20, 2, "dwell", 180, 2.0)

    ent("w-layers-R100-hel45-hoop-hel20", 100, layers_a,
        "three layers in one job on L 300 R 100 mm: helical 45 deg (4 strokes, sine), hoop "
        "(band 15, 2 passes, 4 mm points), helical 20 deg (dwell reversal)",
        {"kind": "layers", "length": 300, "radius": 100, "alpha_deg": [45, 87.8, 20],
         "spacing": [2.0, 4.0, 2.0]})

    def layers_b(tr: Tracer) -> None:
        helical(tr, 250, 40, 65, 2, "cycloid", 180, 0.5)
        helical(tr, 250, 40, 25, 2, "septic", 360, 0.5)

    ent("w-layers-R40-hel65-hel25-0p5mm", 40, layers_b,
        "two helical layers on L 250 R 40 mm: 65 deg (cycloid) then 25 deg (septic), 0.5 mm",
        {"kind": "layers", "length": 250, "radius": 40, "alpha_deg": [65, 25],
         "spacing": 0.5})
    return out
