"""Constant-jerk phases -> a `FeedProfile` (s(t) as a piecewise cubic scipy PPoly), and the
inverse lookup of the path state (v, a, j) at given arc lengths s.

Each phase of duration h starting at (s, v, a) with jerk j is the cubic
s(tau) = s + v tau + a tau^2 / 2 + j tau^3 / 6 for tau in [0, h]; consecutive phases meet
in s, v and a (Ruckig's phases do, to rounding), so s(t) is C2.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PPoly

from lookahead.planning.base import FeedProfile
from lookahead.planning.heuristic.scurve import Phases


def concat_phases(parts: list[Phases]) -> Phases:
    return Phases(*(np.concatenate([getattr(p, f) for p in parts])
                    for f in ("duration", "jerk", "acc", "vel", "pos")))


def build_profile(phases: Phases) -> FeedProfile:
    """The profile of consecutive phases, starting at t = 0."""
    t = np.concatenate([[0.0], np.cumsum(phases.duration)])
    keep = np.diff(t) > 0  # drop phases too short to move the float clock
    starts = t[:-1][keep]
    breaks = np.concatenate([starts, [t[-1]]])
    coeffs = np.stack([phases.jerk[keep] / 6.0, phases.acc[keep] / 2.0,
                       phases.vel[keep], phases.pos[keep]])
    return FeedProfile(PPoly(coeffs, breaks, extrapolate=False))


def state_at_s(profile: FeedProfile, s: np.ndarray) -> np.ndarray:
    """Shape (3, len(s)): feed v, path acceleration a and path jerk j where the profile
    passes arc length s (first passage; s clipped to the profile's range).

    Hand-written because scipy has no vectorized inverse of a monotone PPoly: the piece is
    found by searchsorted on the piece start positions, then a safeguarded Newton iteration
    (bisection fallback inside the piece) solves the cubic for the local time.
    """
    pp = profile.s_of_t
    c = pp.c
    h = np.diff(pp.x)
    s = np.atleast_1d(np.asarray(s, dtype=float))
    piece_start = np.maximum.accumulate(c[3])
    piece_end = ((c[0] * h + c[1]) * h + c[2]) * h + c[3]
    s = np.clip(s, piece_start[0], max(piece_end[-1], piece_start[0]))
    idx = np.clip(np.searchsorted(piece_start, s, side="right") - 1, 0, len(h) - 1)
    c0, c1, c2, c3, width = c[0, idx], c[1, idx], c[2, idx], c[3, idx], h[idx]
    target = s - c3
    rise = piece_end[idx] - c3
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(rise > 0, np.clip(target / rise, 0.0, 1.0) * width, 0.0)
        # start from the root of the quadratic part c1 t^2 + c2 t = target where it has
        # one (cruise and constant-acceleration pieces: exact; elsewhere a few Newton
        # steps fewer than from the chord)
        root = 2.0 * target / (c2 + np.sqrt(np.maximum(c2 * c2 + 4.0 * c1 * target, 0.0)))
        tau = np.where(np.isfinite(root) & (root >= 0.0) & (root <= width), root, tau)
    # the iteration works on compacted copies of the unconverged entries (the first pass,
    # over all of them, needs no gather: most grid points converge in it)
    ids = None
    t, a0, a1, a2, goal, w = tau, c0, c1, c2, target, width
    lo, hi = np.zeros_like(s), width
    for it in range(60):
        if ids is not None and ids.size <= SCALAR_TAIL:
            _newton_tail(tau, 60 - it, ids, t, a0, a1, a2, goal, w, lo, hi)
            break
        f = ((a0 * t + a1) * t + a2) * t - goal
        below = f < 0
        lo = np.where(below, t, lo)
        hi = np.where(below, hi, t)
        fp = (3.0 * a0 * t + 2.0 * a1) * t + a2
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = t - f / fp
        ok = (fp > 0) & (newton >= lo) & (newton <= hi)
        t_new = np.where(ok, newton, 0.5 * (lo + hi))
        if ids is None:
            tau = t_new
            ids = np.arange(s.size)
        else:
            tau[ids] = t_new
        left = np.abs(t_new - t) > 1e-12 * w
        if not left.any():
            break
        ids, t, a0, a1, a2, goal, w, lo, hi = (x[left] for x in (ids, t_new, a0, a1, a2, goal,
                                                                  w, lo, hi))
    v = (3.0 * c0 * tau + 2.0 * c1) * tau + c2
    a = 6.0 * c0 * tau + 2.0 * c1
    j = 6.0 * c0
    return np.stack([v, a, j])


#: `state_at_s` finishes its iteration in scalar Python once this few entries are left
#: unconverged (the same float operations: the same result; numpy's per-call overhead
#: made the last ~15 iterations over 1-3 entries a third of its cost on the corpus)
SCALAR_TAIL = 8


def _newton_tail(tau: np.ndarray, iterations: int, ids: np.ndarray, *arrays: np.ndarray
                 ) -> None:
    """In place: `state_at_s`'s safeguarded Newton iteration for the entries ids of tau,
    entry by entry (arrays: t, a0, a1, a2, goal, w, lo, hi of those entries), for at most
    `iterations` more steps."""
    for i, t, a0, a1, a2, goal, w, lo, hi in zip(ids.tolist(),
                                                 *(x.tolist() for x in arrays),
                                                 strict=True):
        for _ in range(iterations):
            f = ((a0 * t + a1) * t + a2) * t - goal
            if f < 0:
                lo = t
            else:
                hi = t
            fp = (3.0 * a0 * t + 2.0 * a1) * t + a2
            t_new = 0.5 * (lo + hi)
            if fp > 0:
                newton = t - f / fp
                if lo <= newton <= hi:
                    t_new = newton
            tau[i] = t_new
            if not abs(t_new - t) > 1e-12 * w:
                break
            t = t_new
