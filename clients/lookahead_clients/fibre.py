"""Fibre angle laid by a two-axis winder (X carriage mm, C mandrel deg) on a cylinder.

The fibre leaves the carriage at the angle alpha to the mandrel axis with
tan(alpha) = R |dC/dt| / |dX/dt| (C in rad, R the mandrel radius in mm). The winder's path
metric scales C by path_scale = pi/180 * R, so R = path_scale_C * 180 / pi.

A traverse (stroke) is a maximal run of samples on which the commanded carriage speed is at
least `stroke_fraction` (0.8) of the job's largest and keeps one direction: the turnarounds and
the starts and stops, where the angle swings through 90 deg and is ill-conditioned, are not
part of any traverse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def radius_from_path_scale(path_scale_c: float) -> float:
    """Mandrel radius R (mm) from the C axis' path_scale (mm per deg)."""
    return path_scale_c * 180.0 / math.pi


def fibre_angle_deg(vel_x: np.ndarray, vel_c: np.ndarray, radius: float) -> np.ndarray:
    """Angle (deg, 0..90) between fibre and mandrel axis for carriage speed vel_x (mm/s) and
    mandrel speed vel_c (deg/s)."""
    return np.degrees(np.arctan2(radius * np.radians(np.abs(vel_c)), np.abs(vel_x)))


@dataclass(frozen=True)
class Traverse:
    """One stroke: direction of X (+1/-1), sample range, programmed and laid mean angles."""

    direction: int
    start: int
    stop: int
    programmed_deg: float
    laid_deg: float
    max_error_deg: float

    def to_dict(self) -> dict:
        return {"direction": self.direction, "start": self.start, "stop": self.stop,
                "programmed_deg": self.programmed_deg, "laid_deg": self.laid_deg,
                "max_error_deg": self.max_error_deg}


def traverses(vel_cmd: np.ndarray, vel_act: np.ndarray, radius: float,
              stroke_fraction: float = 0.8, x_axis: int = 0, c_axis: int = 1
              ) -> list[Traverse]:
    """The strokes of a job from commanded and actual axis velocities (n, naxes)."""
    vx = vel_cmd[:, x_axis]
    peak = float(np.max(np.abs(vx))) if len(vx) else 0.0
    if peak <= 0.0:
        return []
    direction = np.where(np.abs(vx) >= stroke_fraction * peak, np.sign(vx), 0.0).astype(int)
    # run boundaries: where the direction label changes
    edges = np.flatnonzero(np.diff(direction)) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(direction)]])
    out = []
    for a, b in zip(starts, stops, strict=True):
        if direction[a] == 0 or b - a < 2:
            continue
        programmed = fibre_angle_deg(vx[a:b], vel_cmd[a:b, c_axis], radius)
        laid = fibre_angle_deg(vel_act[a:b, x_axis], vel_act[a:b, c_axis], radius)
        out.append(Traverse(int(direction[a]), int(a), int(b), float(programmed.mean()),
                            float(laid.mean()), float(np.max(np.abs(laid - programmed)))))
    return out


def angle_errors(vel_cmd: np.ndarray, vel_act: np.ndarray, radius: float,
                 strokes: list[Traverse], x_axis: int = 0, c_axis: int = 1) -> np.ndarray:
    """|laid - programmed| angle (deg) on every sample of the given strokes."""
    parts = []
    for tr in strokes:
        sl = slice(tr.start, tr.stop)
        programmed = fibre_angle_deg(vel_cmd[sl, x_axis], vel_cmd[sl, c_axis], radius)
        laid = fibre_angle_deg(vel_act[sl, x_axis], vel_act[sl, c_axis], radius)
        parts.append(np.abs(laid - programmed))
    return np.concatenate(parts) if parts else np.zeros(0)
