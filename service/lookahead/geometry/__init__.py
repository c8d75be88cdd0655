"""Input geometry: curves in axis space, arc length, fits, kinematics, patterns, G-code."""

from lookahead.geometry.base import Path

__all__ = ["Path"]
