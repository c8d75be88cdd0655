"""Per-axis kinematic limits of a machine."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AxisLimits:
    """Limits of each axis, in the axis' own unit (mm or deg) per s, s^2, s^3.

    Arrays have shape (naxes,); all entries are finite and > 0.
    """

    vmax: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray

    def __post_init__(self) -> None:
        for name in ("vmax", "amax", "jmax"):
            arr = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ValueError(f"{name} must be finite and > 0 for every axis, got {arr}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if not (self.vmax.shape == self.amax.shape == self.jmax.shape):
            raise ValueError("vmax, amax and jmax must have one entry per axis")

    @property
    def naxes(self) -> int:
        return int(self.vmax.shape[0])

    def same_as(self, other: AxisLimits) -> bool:
        """True if both limits are equal exactly, per axis."""
        return self is other or (np.array_equal(self.vmax, other.vmax)
                                 and np.array_equal(self.amax, other.amax)
                                 and np.array_equal(self.jmax, other.jmax))

    def scaled(self, factor: float) -> AxisLimits:
        """The same limits times `factor` (e.g. 0.98 for a planning margin)."""
        return AxisLimits(self.vmax * factor, self.amax * factor, self.jmax * factor)
