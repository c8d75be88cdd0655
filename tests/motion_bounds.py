"""Time-optimal reference motions for the tests (Ruckig), to judge planners against."""

from __future__ import annotations

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Trajectory

from lookahead.limits import AxisLimits


def rest_to_rest_duration(displacement: np.ndarray, limits: AxisLimits) -> float:
    """Time-optimal synchronized straight move from rest to rest at the axis limits (s)."""
    n = displacement.size
    inp = InputParameter(n)
    inp.current_position = [0.0] * n
    inp.target_position = list(displacement)
    inp.max_velocity = list(limits.vmax)
    inp.max_acceleration = list(limits.amax)
    inp.max_jerk = list(limits.jmax)
    trajectory = Trajectory(n)
    assert Ruckig(n).calculate(inp, trajectory) == Result.Working
    return trajectory.duration
