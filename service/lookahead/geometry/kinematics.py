"""Inverse kinematics: workpiece-frame poses -> machine axes.

Two-drive filament winder: the mandrel axis is the workpiece x axis. A fibre contact point
(x, y, z) in mm maps to X = x (carriage, mm along the mandrel) and C = atan2(z, y) in
degrees, unwrapped so that C is continuous through 360 (each step takes the smaller turn).
Orientation vectors (n, 3), e.g. the fibre direction, are validated and ignored here;
they are kept in the interface for machines with more axes (payout eye, tilt).
Axis-space input needs no kinematics: `AxisIdentity`.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

#: contact points closer than this (mm) to the mandrel axis have no defined angle
MIN_RADIUS = 1e-9


class Kinematics(Protocol):
    """Maps workpiece-frame poses to machine axis positions."""

    axes: tuple[str, ...]

    def inverse(self, points: np.ndarray, orientations: np.ndarray | None = None) -> np.ndarray:
        """Machine axis positions (n, len(axes)) for poses `points` (n, 3)."""
        ...


def _checked(arr: np.ndarray | None, what: str, width: int) -> np.ndarray | None:
    if arr is None:
        return None
    arr = np.asarray(arr, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{what}: expected shape (n, {width}), got {arr.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
    if bad.size:
        raise ValueError(f"{what}[{bad[0]}] is not finite: {arr[bad[0]].tolist()}")
    return arr


class TwoDriveWinder:
    """X (mm) and C (deg, unwrapped) from contact points on the mandrel (mandrel axis = x).

    `c_start` (deg) picks the revolution of the first point: its C lies in
    [c_start - 180, c_start + 180).
    """

    axes = ("X", "C")

    def __init__(self, c_start: float = 0.0) -> None:
        self.c_start = float(c_start)

    def inverse(self, points: np.ndarray, orientations: np.ndarray | None = None) -> np.ndarray:
        pts = _checked(points, "points", 3)
        assert pts is not None
        ori = _checked(orientations, "orientations", 3)
        if ori is not None and len(ori) != len(pts):
            raise ValueError(f"orientations: expected {len(pts)} rows, got {len(ori)}")
        radius = np.hypot(pts[:, 1], pts[:, 2])
        bad = np.flatnonzero(radius < MIN_RADIUS)
        if bad.size:
            raise ValueError(f"points[{bad[0]}] lies on the mandrel axis: its angle is undefined")
        c = np.degrees(np.unwrap(np.arctan2(pts[:, 2], pts[:, 1])))
        if c.size:
            c += 360.0 * np.round((self.c_start - c[0]) / 360.0)
        return np.column_stack([pts[:, 0], c])


class AxisIdentity:
    """Segments already in machine axes: positions pass through (validated, copied)."""

    def __init__(self, axes: tuple[str, ...] | list[str]) -> None:
        self.axes = tuple(axes)

    def inverse(self, points: np.ndarray, orientations: np.ndarray | None = None) -> np.ndarray:
        pts = _checked(points, "points", len(self.axes))
        assert pts is not None
        return pts.copy()
