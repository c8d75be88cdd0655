"""A simulated position-servo drive per axis: what the winder's motors do with setpoints.

Model (per axis, axis units mm or deg): a rigid inertia whose acceleration is the drive's
command, saturated at `saturation * amax` (the drive's torque limit). The command is a PD
position loop plus velocity and acceleration feedforward:

    a = clip(ff * acc_cmd + kp * (pos_cmd - x) + kd * (vel_cmd - v), -a_sat, a_sat)

with kp = w^2, kd = 2 zeta w, w = 2 pi bandwidth_hz. The acceleration feedforward gain `ff`
is below 1 on purpose (the drive's inertia estimate is a little low, as on a real machine),
so the following error is small but not zero. The drive runs on the sample clock dt: the
command is held over each sample (zero-order hold) and the double integrator is integrated
exactly over it.

Written by hand (a loop over samples): the saturation makes the model nonlinear, so
scipy's linear-system simulators do not apply, and a per-sample update is what a drive does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ServoTuning:
    """Loop tuning shared by all axes."""

    bandwidth_hz: float = 30.0
    damping: float = 0.9
    accel_feedforward: float = 0.95
    #: acceleration saturation as a multiple of the axis' amax
    saturation: float = 1.5


class PositionServo:
    """All axes of one machine; state x (position) and v (velocity) per axis."""

    def __init__(self, amax: np.ndarray, dt: float, tuning: ServoTuning | None = None) -> None:
        self.tuning = tuning or ServoTuning()
        self.dt = float(dt)
        w = 2.0 * math.pi * self.tuning.bandwidth_hz
        self._kp = w * w
        self._kd = 2.0 * self.tuning.damping * w
        self._a_sat = self.tuning.saturation * np.asarray(amax, dtype=float)
        self.x = np.zeros(len(self._a_sat))
        self.v = np.zeros(len(self._a_sat))
        self.saturated = 0  # samples on which at least one axis hit its saturation

    def reset(self, pos: np.ndarray) -> None:
        """Put the machine at rest at `pos`."""
        self.x = np.array(pos, dtype=float)
        self.v = np.zeros_like(self.x)

    def run(self, pos_cmd: np.ndarray, vel_cmd: np.ndarray, acc_cmd: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
        """Execute n setpoints (n, naxes); return the actual positions and velocities at the
        samples' due times (before each sample's command acts), both (n, naxes)."""
        n = len(pos_cmd)
        xs = np.empty((n, len(self.x)))
        vs = np.empty_like(xs)
        dt, kp, kd, ff, sat = self.dt, self._kp, self._kd, self.tuning.accel_feedforward, \
            self._a_sat
        x, v = self.x, self.v
        for k in range(n):
            xs[k] = x
            vs[k] = v
            a = ff * acc_cmd[k] + kp * (pos_cmd[k] - x) + kd * (vel_cmd[k] - v)
            if np.any(np.abs(a) > sat):
                self.saturated += 1
                a = np.clip(a, -sat, sat)
            x = x + v * dt + 0.5 * a * dt * dt
            v = v + a * dt
        self.x, self.v = x, v
        return xs, vs
