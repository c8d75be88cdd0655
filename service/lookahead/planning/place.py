"""Where on a path a planner failed: arc length s and the nearest programmed point.

A planning failure is reported with its place (issue 13: "one line with the planner, the
place on the path (s and the point index) and the reason"). s is arc length in path units;
the point index counts the knots of the path's fit (for a `points` job, its distinct
points; repeated points were dropped before the fit).
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.planning.base import PlanningError


class PlacedPlanningError(PlanningError):
    """A PlanningError that knows where on the path it happened (`s`, path units)."""

    def __init__(self, message: str, s: float) -> None:
        super().__init__(message)
        self.s = float(s)


def failure_s(exc: BaseException, default: float) -> float:
    """The arc length an exception names (`PlacedPlanningError.s`), else `default`."""
    s = getattr(exc, "s", None)
    return float(s) if s is not None else float(default)


def point_index(path: Path, s: float) -> int:
    """Index of the last knot of the path's fit at or before s (0-based)."""
    knots = np.asarray(path.breakpoints_s(), dtype=float)
    if knots.size == 0:
        return 0
    return int(max(np.searchsorted(knots, s, side="right") - 1, 0))


def describe_place(path: Path, s: float) -> str:
    """'s=123.456 (point 78)'."""
    return f"s={s:.6g} (point {point_index(path, s)})"
