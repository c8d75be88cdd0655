"""NURBS test curves of the feedrate-planning literature, sent as `nurbs` segments.

- The butterfly: degree 3, 51 control points, weights and knots as published in
  Y. Hu, X. Jiang, G. Huo et al., "A novel method for calculating interpolation points of
  NURBS curves based on chord length-parameter ratio", Int J Adv Manuf Technol 129,
  2843-2860 (2023), doi:10.1007/s00170-023-12427-5 (the same butterfly appears in many
  feedrate papers). Machine: X/Y, 150 mm/s, 1500 mm/s^2, 20000 mm/s^3 per axis.
  The published knots are rounded to 4 digits; used as printed.
- Exact conics as rational quadratics (textbook construction, Piegl & Tiller ch. 7): a
  full circle (9 control points, weights 1, sqrt(2)/2) and an ellipse from it.
- Curves designed here (not published data): a heart and a seeded 5-lobed flower, cubic
  NURBS with non-uniform weights; and the butterfly discretized into points (as a CAM
  post-processor would emit it) for the point-stream fit.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline

from bench.corpus.base import (
    CorpusPath,
    Piece,
    clamped_knots,
    machine_config,
    piece_segments,
    point_segments,
    rng_for,
)

BUTTERFLY_CTRL = np.array([
    (54.493, 52.139), (55.507, 52.139), (56.082, 49.615), (56.780, 44.971),
    (69.575, 51.358), (77.786, 58.573), (90.526, 67.081), (105.973, 63.801),
    (100.400, 47.326), (94.567, 39.913), (92.369, 30.485), (83.440, 33.757),
    (91.892, 28.509), (89.444, 20.393), (83.218, 15.446), (87.621, 4.830),
    (80.945, 9.267), (79.834, 14.535), (76.074, 8.522), (70.183, 12.550),
    (64.171, 16.865), (59.993, 22.122), (55.680, 36.359), (56.925, 24.995),
    (59.765, 19.828), (54.493, 14.940), (49.220, 19.828), (52.060, 24.994),
    (53.305, 36.359), (48.992, 22.122), (44.814, 16.865), (38.802, 12.551),
    (32.911, 8.521), (29.152, 14.535), (28.040, 9.267), (21.364, 4.830),
    (25.768, 15.447), (19.539, 20.391), (17.097, 28.512), (25.537, 33.750),
    (16.602, 30.496), (14.199, 39.803), (8.668, 47.408), (3.000, 63.794),
    (18.465, 67.084), (31.197, 58.572), (39.411, 51.358), (52.204, 44.971),
    (52.904, 49.614), (53.478, 52.139), (54.492, 52.139),
])
BUTTERFLY_KNOTS = np.array([
    0, 0, 0, 0, 0.0083, 0.015, 0.0361, 0.0855, 0.1293, 0.1509, 0.1931, 0.2273, 0.2435,
    0.2561, 0.2692, 0.2889, 0.3170, 0.3316, 0.3482, 0.3553, 0.3649, 0.3837, 0.4005, 0.4269,
    0.4510, 0.4660, 0.4891, 0.5000, 0.5109, 0.5340, 0.5489, 0.5731, 0.5994, 0.6163, 0.6351,
    0.6447, 0.6518, 0.6683, 0.6830, 0.7111, 0.7307, 0.7439, 0.7565, 0.7729, 0.8069, 0.8491,
    0.8707, 0.9145, 0.9639, 0.9850, 0.9917, 1, 1, 1, 1,
])
BUTTERFLY_WEIGHTS = np.array([
    1.0, 1.0, 1.0, 1.2, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 1.0, 1.0, 5.0, 3.0, 1.0,
    1.1, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.1,
    1.0, 3.0, 5.0, 1.0, 1.0, 2.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.2, 1.0, 1.0, 1.0,
])


def butterfly_config():
    """The butterfly's machine: X/Y, 150 mm/s, 1500 mm/s^2, 20000 mm/s^3 per axis."""
    return machine_config(["X", "Y"], ["mm", "mm"], [150.0] * 2, [1500.0] * 2,
                          [20000.0] * 2, machine_id="xy")


def butterfly() -> list[Piece]:
    return [Piece(3, BUTTERFLY_KNOTS, BUTTERFLY_CTRL, BUTTERFLY_WEIGHTS)]


def circle(radius: float, centre: tuple[float, float] = (0.0, 0.0),
           stretch: tuple[float, float] = (1.0, 1.0)) -> list[Piece]:
    """The full circle (or, with `stretch`, an ellipse) as a rational quadratic starting
    at angle 0: 9 control points on the circumscribed square, knots at the quarters."""
    c = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1],
                  [1, 0]], dtype=float)
    ctrl = np.asarray(centre) + radius * c * np.asarray(stretch)
    w = np.array([1, math.sqrt(0.5)] * 4 + [1])
    knots = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])
    return [Piece(2, knots, ctrl, w)]


def heart() -> list[Piece]:
    """A heart (designed here): cubic NURBS, 11 control points, two heavy weights at the
    lobes, a sharp-ish dip at the top (mm)."""
    ctrl = np.array([[0, 0], [15, 15], [35, 35], [45, 60], [25, 75], [5, 60], [0, 50],
                     [-5, 60], [-25, 75], [-45, 60], [-35, 35]], dtype=float)
    ctrl = np.vstack([ctrl, [[-15, 15], [0, 0]]])
    w = np.ones(len(ctrl))
    w[[3, 9]] = 2.5
    w[6] = 0.6
    return [Piece(3, clamped_knots(len(ctrl), 3), ctrl, w)]


def flower(name: str, lobes: int = 5, per_lobe: int = 4) -> list[Piece]:
    """A seeded `lobes`-lobed closed-ish flower (designed here), cubic NURBS with random
    weights in [0.5, 3] (mm)."""
    rng = rng_for(name)
    m = lobes * per_lobe
    th = np.linspace(0, 2 * np.pi, m + 1)
    r = 40 + 25 * np.cos(lobes * th) + rng.uniform(-3, 3, size=m + 1)
    ctrl = np.column_stack([r * np.cos(th), r * np.sin(th)])
    w = rng.uniform(0.5, 3.0, size=m + 1)
    return [Piece(3, clamped_knots(len(ctrl), 3), ctrl, w)]


def nurbs_points(pieces: list[Piece], n: int) -> np.ndarray:
    """n points on the curve at uniform parameter steps (a CAM-style discretization)."""
    p = pieces[0]
    w = np.asarray(p.weights, dtype=float)
    hom = BSpline(p.knots, np.column_stack([p.ctrl * w[:, None], w]), p.degree)
    u = np.linspace(p.knots[0], p.knots[-1], n)
    h = hom(u)
    return h[:, :-1] / h[:, -1:]


def _entry(name, cfg, pieces_fn, desc, params, fast=False):
    axes = cfg.machine.axes
    return CorpusPath(name, "cnc", cfg, lambda job: piece_segments(job, axes, pieces_fn()),
                      notes=desc, params=params, fast=fast)


def corpus() -> list[CorpusPath]:
    bf = butterfly_config()
    xy = machine_config(["X", "Y"], ["mm", "mm"], [200.0] * 2, [2000.0] * 2, [40000.0] * 2)
    out = [
        _entry("n-butterfly", bf, butterfly,
               "the butterfly NURBS of the feedrate literature (published data, Hu et al. "
               "2023), X/Y 150 mm/s, 1500 mm/s^2, 20000 mm/s^3 (issue 13)",
               {"kind": "nurbs", "source": "Hu et al. 2023, doi:10.1007/s00170-023-12427-5"},
               fast=True),
        _entry("n-circle-R30", xy, lambda: circle(30.0),
               "full circle R 30 mm as an exact rational quadratic NURBS",
               {"kind": "nurbs", "radius": 30.0}, fast=True),
        _entry("n-ellipse-80x20", xy, lambda: circle(40.0, stretch=(1.0, 0.25)),
               "ellipse 80 x 20 mm as an exact rational quadratic NURBS",
               {"kind": "nurbs"}),
        _entry("n-heart", xy, heart, "a heart (designed here), cubic NURBS, weights 0.6..2.5",
               {"kind": "nurbs"}),
        _entry("n-flower-5lobes", xy, lambda: flower("n-flower-5lobes"),
               "a 5-lobed flower (designed here, seeded), cubic NURBS, weights 0.5..3",
               {"kind": "nurbs"}),
    ]
    axes = bf.machine.axes
    out.append(CorpusPath(
        "n-butterfly-points-1500", "cnc", bf,
        lambda job: point_segments(job, axes, nurbs_points(butterfly(), 1500), 150),
        notes="the butterfly discretized at 1500 uniform parameter steps (as points, cubic "
              "fit), same machine", params={"kind": "nurbs-points", "npoints": 1500}))
    return out
