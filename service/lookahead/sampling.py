"""The sampler: a feed profile s(t) on a path -> axis positions, velocities, accelerations.

Samples lie exactly on the path: pos = x(s(t)), vel = x_s v, acc = x_ss v^2 + x_s a
(chain rule in arc length s; v = ds/dt, a = d2s/dt2), axis units and seconds.

Near-zero feed (paper 2.3): interpolators that integrate the feed (Taylor expansions of
u(t)) lose accuracy or divide by the feed when it is small. Here nothing is integrated: the
profile gives s(t) in closed form, and u(s) is the path's own arc-length inverse, which is
well conditioned at any feed. What remains is rounding: s(t) of a profile that stops can
wobble by ~1e-16 relative around its stopping point, so s is clipped to the profile's range
and made non-decreasing along the (sorted) sample times, and v is clipped at 0, so a stopped
machine never creeps backwards.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lookahead.geometry.base import Path
from lookahead.planning.base import FeedProfile


@dataclass(frozen=True)
class Samples:
    """Axis setpoints, each of shape (n, naxes), in axis units, per s and per s^2."""

    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray

    def __len__(self) -> int:
        return int(self.pos.shape[0])


def _robust_path_state(profile: FeedProfile, t: np.ndarray, raw: np.ndarray | None = None
                       ) -> tuple[np.ndarray, ...]:
    """s, v, a at times t with the near-zero-feed guards described in the module doc.
    raw: `profile.at(t)` if the caller has it already (rows s, v, a[, j])."""
    s, v, a = (profile.at(t) if raw is None else raw)[:3]
    s_lo = float(profile.s_of_t(profile.s_of_t.x[0]))
    s_hi = float(profile.s_of_t(profile.s_of_t.x[-1]))
    s = np.clip(s, min(s_lo, s_hi), max(s_lo, s_hi))
    if t.size > 1 and np.all(np.diff(t) >= 0):
        s = np.maximum.accumulate(s)
    return s, np.maximum(v, 0.0), a


def sample_profile(path: Path, profile: FeedProfile, t: np.ndarray,
                   raw: np.ndarray | None = None) -> Samples:
    """Axis pos/vel/acc at profile times t (s from the profile's start; clipped to it).
    raw: profile.at(t) (rows s, v, a[, j]) when the caller has evaluated it already (the
    same values: `FeedProfile.at` is pointwise)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    s, v, a = _robust_path_state(profile, t, raw)
    d = path.eval_s(s, order=2)
    vel = d[1] * v[:, None]
    acc = d[2] * (v * v)[:, None] + d[1] * a[:, None]
    return Samples(pos=d[0], vel=vel, acc=acc)


def sample_times(duration: float, dt: float) -> np.ndarray:
    """t = k dt for k = 0..ceil(duration/dt) (the last sample at or after the end)."""
    n = math.ceil(duration / dt - 1e-9)
    return np.arange(max(n, 0) + 1) * dt


def sample_plan(path: Path, profile: FeedProfile, dt: float) -> Samples:
    """Samples at t = k dt, k = 0..ceil(T/dt); times past the end hold the end state."""
    return sample_profile(path, profile, sample_times(profile.duration, dt))
