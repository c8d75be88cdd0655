"""The fits of a point stream by name (PROTOCOL.md `fit`), streamed or of a whole set.

`cubic` / `pchip` interpolate the points (`StreamingFit`); `linear` follows their polyline
with corner blends within a tolerance (`LinearFit`); `smooth` approximates it within a
tolerance with few pieces (`SmoothFit`). Tolerances in path units; the interpolating fits
ignore it (their excursions are reported by `deviation.excursions`).
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.geometry.polyline import DEFAULT_TOLERANCE, LinearFit
from lookahead.geometry.smoothing import SmoothFit
from lookahead.geometry.streaming import MIN_STEP, StreamingFit

FITS = ("cubic", "pchip", "linear", "smooth")
#: fits that follow the polyline within a tolerance
TOLERANCE_FITS = ("linear", "smooth")

AnyStreamingFit = StreamingFit | LinearFit | SmoothFit


def make_streaming_fit(naxes: int, path_scale: np.ndarray, method: str = "cubic",
                       tolerance: float = DEFAULT_TOLERANCE, min_step: float = MIN_STEP
                       ) -> AnyStreamingFit:
    """A streaming fit of `method`; `tolerance` is the default of `linear` / `smooth`."""
    if method == "linear":
        return LinearFit(naxes, path_scale, tolerance, min_step)
    if method == "smooth":
        return SmoothFit(naxes, path_scale, tolerance, min_step)
    if method not in FITS:
        raise ValueError(f"fit: unknown method {method!r}, expected one of {FITS}")
    return StreamingFit(naxes, path_scale, method, min_step)


def extend_fit(fit: AnyStreamingFit, points: np.ndarray,
               tolerance: float | np.ndarray | None = None) -> None:
    """`fit.extend(points)`, with the tolerance for the fits that take one."""
    if isinstance(fit, LinearFit | SmoothFit):
        fit.extend(points, tolerance)
    else:
        fit.extend(points)


def fit_path(points: np.ndarray, path_scale: np.ndarray, method: str = "cubic",
             tolerance: float | np.ndarray | None = None,
             default_tolerance: float = DEFAULT_TOLERANCE) -> Path:
    """The whole point set (n, naxes) fitted with `method` (repeats skipped): the same
    geometry the service builds from a stream of them. `tolerance`: one value or one per
    point (None: `default_tolerance`)."""
    path_scale = np.asarray(path_scale, dtype=float).reshape(-1)
    fit = make_streaming_fit(path_scale.size, path_scale, method, default_tolerance)
    extend_fit(fit, points, tolerance)
    return fit.finish()
