"""Fits of a whole point stream, parameterized by cumulative chord length u in the path
metric (so u approximates s): `cubic` (C2 interpolating, scipy CubicSpline, not-a-knot
ends) and `pchip` (C1 shape-preserving, scipy PchipInterpolator: never overshoots its
data). `SplinePath` is a `PiecewisePath` over the fitted PPoly.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator, PPoly

from lookahead.geometry.arclength import Leaves
from lookahead.geometry.piecewise import PiecewisePath

FIT_METHODS = ("cubic", "pchip")


class SplinePath(PiecewisePath):
    """x(u) given as a scipy PPoly with values of shape (naxes,), u over its breakpoints.

    `continuity` is declared by the caller (2 for a cubic spline, 1 for pchip).
    `leaves` optionally reuses already integrated arc-length leaves (`PiecewisePath.leaves`).
    """

    def __init__(
        self,
        pp: PPoly,
        path_scale: np.ndarray,
        continuity: int = 2,
        leaves: Leaves | None = None,
    ) -> None:
        super().__init__(pp, path_scale, continuity=continuity, leaves=leaves)


def validate_points(points: np.ndarray, naxes: int, what: str = "points") -> np.ndarray:
    """`points` as a float array (n, naxes); ValueError naming the first bad row."""
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1 and naxes == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] != naxes:
        raise ValueError(f"{what}: expected shape (n, {naxes}), got {arr.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
    if bad.size:
        raise ValueError(f"{what}[{bad[0]}] is not finite: {arr[bad[0]].tolist()}")
    return arr


def chord_parameters(points: np.ndarray, path_scale: np.ndarray) -> np.ndarray:
    """Cumulative chord length of `points` (n, naxes) in the path metric, starting at 0."""
    steps = np.sqrt(np.sum((np.diff(points, axis=0) * path_scale) ** 2, axis=1))
    return np.concatenate([[0.0], np.cumsum(steps)])


def fit_points(points: np.ndarray, path_scale: np.ndarray, method: str = "cubic") -> SplinePath:
    """Fit a point stream (n, naxes), n >= 2, with distinct consecutive points.

    method: 'cubic' (C2 interpolating, not-a-knot ends) or 'pchip' (C1, shape-preserving).
    The parameter u is the cumulative chord length in the path metric. ValueError names
    the offending row for NaN/inf, a wrong shape or a repeated point.
    """
    path_scale = np.asarray(path_scale, dtype=float).reshape(-1)
    points = validate_points(points, path_scale.size)
    if len(points) < 2:
        raise ValueError(f"points: need at least 2 points, got {len(points)}")
    u = chord_parameters(points, path_scale)
    repeated = np.flatnonzero(np.diff(u) <= 0)
    if repeated.size:
        raise ValueError(f"points[{repeated[0] + 1}] repeats the previous point")
    if method == "cubic":
        bc = "not-a-knot" if len(u) > 3 else "natural"
        return SplinePath(CubicSpline(u, points, axis=0, bc_type=bc), path_scale, continuity=2)
    if method == "pchip":
        return SplinePath(PchipInterpolator(u, points, axis=0), path_scale, continuity=1)
    raise ValueError(f"fit: unknown method {method!r}, expected 'cubic' or 'pchip'")
