"""Corner blends for the `linear` fit: a quintic Bezier inside the corner of two lines.

Frames and units: points in axis units; directions D1, D2 in axis units per unit of the
line parameter u (u is the chord length in the path metric, so |path_scale * D| = 1 on a
line up to rounding); lengths and tolerances in path units (the metric
||path_scale * dx||).

The blend at a vertex P between the incoming line (direction D1) and the outgoing one (D2)
has control points on the two lines, at parameter distances l1, c1 l1, c2 l1 before P and
c2 l2, c1 l2, l2 after it (0 <= c2 <= c1 <= 1; l1 = l2 for a symmetric blend). Three
collinear control points at each end make the curvature 0 there, so the blend meets its
lines with matching tangent and zero curvature (G2: x_ss continuous in arc length) and
the jerk stays bounded through it.

Its deviation from the two lines, in closed form: the distance from the incoming line is
l2 sin(theta) sigma2 A(t), A = (c2 b3 + c1 b4 + b5) (b_i the Bernstein polynomials, theta
the turning angle, sigma2 = |path_scale D2|), increasing in t because the coefficients
increase; the distance from the outgoing line is l1 sin(theta) sigma1 A(1 - t). The curve
is furthest from the polyline where the two are equal: at t = 1/2 for a symmetric blend,
exactly l sin(theta) sigma (1 + 5 c1 + 10 c2) / 32; else on the side of the shorter
half, where A <= A(1/2), so at most max(l1, l2) times that factor. (Every foot point lies
on the segments themselves, between P and the blend's ends.)
"""

from __future__ import annotations

import math

import numpy as np

#: optimal control-point distances (c1, c2) by turning angle (deg): they maximize the
#: jerk-limited feed through a blend of given tolerance (min of max |x_sss|, isotropic
#: limits), found by Nelder-Mead on a dense sampling of the blend at each angle; (0.6,
#: 0.2), equal spacing, is 10-80 % slower at 5-175 deg. Interpolated linearly between.
_SHAPE_DEG = np.array([0.0, 5.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0, 135.0,
                       150.0, 160.0, 170.0, 175.0, 180.0])
_SHAPE_C1 = np.array([0.599, 0.599, 0.598, 0.597, 0.598, 0.590, 0.588, 0.586, 0.632, 0.678,
                      0.733, 0.803, 0.859, 0.924, 0.961, 0.961])
_SHAPE_C2 = np.array([0.147, 0.147, 0.150, 0.159, 0.173, 0.208, 0.249, 0.299, 0.356, 0.431,
                      0.524, 0.640, 0.735, 0.851, 0.920, 0.920])


def blend_shape(theta: float) -> tuple[float, float]:
    """(c1, c2) for a turning angle theta (rad), 0 <= c2 <= c1 <= 1."""
    deg = math.degrees(theta)
    return float(np.interp(deg, _SHAPE_DEG, _SHAPE_C1)), float(np.interp(deg, _SHAPE_DEG,
                                                                         _SHAPE_C2))


def turn_angle(d1: np.ndarray, d2: np.ndarray) -> float:
    """Angle (rad, 0..pi) between unit vectors d1 and d2 (stable for small and large)."""
    return 2.0 * math.atan2(float(np.linalg.norm(d2 - d1)), float(np.linalg.norm(d2 + d1)))


def deviation_factor(theta: float, c1: float, c2: float, sigma: float = 1.0) -> float:
    """Largest distance (path units) of a blend of half-length l = 1 from its two lines."""
    return math.sin(theta) * sigma * (1.0 + 5.0 * c1 + 10.0 * c2) / 32.0


#: power-basis coefficients of the degree-5 Bernstein polynomials: row j = coefficient of
#: t^j, column i = control point i
_BERNSTEIN5 = np.array([[math.comb(5, j) * math.comb(j, i) * (-1) ** (j - i) if i <= j else 0
                         for i in range(6)] for j in range(6)], dtype=float)


def blend_coefficients(vertex: np.ndarray, d1: np.ndarray, d2: np.ndarray, half_in: float,
                       half_out: float, c1: float, c2: float) -> np.ndarray:
    """PPoly coefficients (6, naxes), highest power first, of the blend over the local
    offset h in [0, half_in + half_out] from its start (u = u_vertex - half_in + h)."""
    ctrl = np.stack([vertex - half_in * d1, vertex - c1 * half_in * d1,
                     vertex - c2 * half_in * d1, vertex + c2 * half_out * d2,
                     vertex + c1 * half_out * d2, vertex + half_out * d2])
    power_t = _BERNSTEIN5 @ ctrl  # row j: coefficient of t^j
    width = half_in + half_out
    scale = width ** -np.arange(6.0)  # t = h / width
    return (power_t * scale[:, None])[::-1]
