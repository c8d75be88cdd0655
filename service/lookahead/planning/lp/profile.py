"""From feed values on an s-grid to a C2 feed profile s(t).

Each grid interval [s_i, s_i+1] becomes one quintic in t with the nodal state
(s, v = sqrt(q), a = q'/2) at both ends (Hermite data), so s(t) is C2 by construction
and starts exactly in the requested state. The interval's duration is free: the
duration is chosen so that the quintic degenerates to a quartic (jerk linear in t, no
spurious position-correcting jerk, which scales like 60 dh / T^3); where that is not
possible, the duration near the trapezoid time of least peak path jerk (hand-written:
a vectorized scan, scipy has no batched scalar minimizer). No interval may reverse
(ds/dt < 0: the sampler holds s, the checker sees a jerk spike); where no duration avoids
it, the node accelerations there become the interval's secant (`secant_accelerations`).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PPoly

from lookahead.planning.base import FeedProfile, PlanningError
from lookahead.planning.lp.rows import backward_slope_weights, fd_weights

_COARSE = np.linspace(0.6, 1.8, 49)
_FINE = np.linspace(-1.0, 1.0, 21)


def node_accelerations(
    s: np.ndarray, q: np.ndarray, a_start: float, a_end: float | None
) -> np.ndarray:
    """Path acceleration q'/2 at the nodes (0 at interior nodes at rest); the end values
    are given (None: backward slope)."""
    a = np.empty_like(q)
    w1, _ = fd_weights(s)
    a[1:-1] = 0.5 * (w1[:, 0] * q[:-2] + w1[:, 1] * q[1:-1] + w1[:, 2] * q[2:])
    # an interior node at rest (a corner's stop) has path acceleration 0: a central slope
    # there is nonzero on an asymmetric grid (a refined side, `lp.grid.refine_grid`) and
    # the feed would reverse
    a[1:-1][q[1:-1] <= 0.0] = 0.0
    a[0] = a_start
    a[-1] = 0.5 * float(backward_slope_weights(s) @ q[-3:]) if a_end is None else a_end
    return a


def quintic_coefficients(
    T: np.ndarray, h: np.ndarray, v0: np.ndarray, a0: np.ndarray, v1: np.ndarray,
    a1: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """c3, c4, c5 of s(tau) = v0 tau + a0 tau^2/2 + c3 tau^3 + c4 tau^4 + c5 tau^5 (s(0)=0)
    reaching (h, v1, a1) at tau = T."""
    d0 = h - v0 * T - 0.5 * a0 * T**2
    d1 = v1 - v0 - a0 * T
    d2 = a1 - a0
    c3 = (10.0 * d0 - 4.0 * d1 * T + 0.5 * d2 * T**2) / T**3
    c4 = (-15.0 * d0 + 7.0 * d1 * T - d2 * T**2) / T**4
    c5 = (6.0 * d0 - 3.0 * d1 * T + 0.5 * d2 * T**2) / T**5
    return c3, c4, c5


def _peak_jerk_and_min_speed(T, h, v0, a0, v1, a1):
    c3, c4, c5 = quintic_coefficients(T, h, v0, a0, v1, a1)
    tau = T[..., None] * np.linspace(0.0, 1.0, 9)
    jerk = 6.0 * c3[..., None] + 24.0 * c4[..., None] * tau + 60.0 * c5[..., None] * tau**2
    speed = (v0[..., None] + a0[..., None] * tau + 3.0 * c3[..., None] * tau**2
             + 4.0 * c4[..., None] * tau**3 + 5.0 * c5[..., None] * tau**4)
    return np.max(np.abs(jerk), axis=-1), np.min(speed, axis=-1)


def _best_factor(factors, T_ref, h, v0, a0, v1, a1):
    """For each interval, the factor (row of `factors`) of least peak jerk, no reversal."""
    T = T_ref[:, None] * factors
    args = [x[:, None] for x in (h, v0, a0, v1, a1)]
    peak, vmin = _peak_jerk_and_min_speed(T, *args)
    peak = np.where(vmin >= -1e-9 * (1.0 + np.abs(args[1]) + np.abs(args[3])), peak, np.inf)
    return factors[np.arange(T.shape[0]), np.argmin(peak, axis=1)]


def consistent_durations(h: np.ndarray, v0, a0, v1, a1) -> np.ndarray:
    """The duration T that makes the quintic a quartic (c5 = 0, jerk linear in t).

    c5 = 0 is h = T (v0 + v1) / 2 + T^2 (a0 - a1) / 12, the integral of the cubic Hermite
    speed; it gives the trapezoid time when a0 = a1 and the exact time of a constant-jerk
    start from rest. The smaller root; NaN where none is real and positive.
    """
    beta = 3.0 * (v0 + v1)
    disc = beta**2 - 12.0 * (a1 - a0) * h
    with np.errstate(invalid="ignore", divide="ignore"):
        T = 12.0 * h / (beta + np.sqrt(disc))
    return np.where((disc >= 0) & (T > 0) & np.isfinite(T), T, np.nan)


def interval_durations(h: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Duration of each interval (`durations_and_reversals`, without the flags)."""
    return durations_and_reversals(h, v, a)[0]


def durations_and_reversals(h: np.ndarray, v: np.ndarray, a: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Duration of each interval: the quartic-making time where it exists and keeps the
    speed >= 0, else the least-peak-jerk choice around the trapezoid time; and whether
    the interval's speed still goes below 0 (no candidate duration avoids a reversal)."""
    vsum = v[:-1] + v[1:]
    if np.any(vsum <= 0.0):
        raise PlanningError("the feed vanishes on a whole grid interval (stalls)")
    v0, v1, a0, a1 = v[:-1], v[1:], a[:-1], a[1:]
    T = consistent_durations(h, v0, a0, v1, a1)
    ok = np.isfinite(T)
    _, vmin = _peak_jerk_and_min_speed(np.where(ok, T, 1.0), h, v0, a0, v1, a1)
    ok &= vmin >= -1e-9 * (1.0 + v0 + v1)
    bad = ~ok
    if np.any(bad):
        T_ref = 2.0 * h[bad] / vsum[bad]
        args = (h[bad], v0[bad], a0[bad], v1[bad], a1[bad])
        n = T_ref.size
        f = _best_factor(np.broadcast_to(_COARSE, (n, _COARSE.size)), T_ref, *args)
        fine = f[:, None] + (_COARSE[1] - _COARSE[0]) * _FINE[None, :]
        T[bad] = T_ref * _best_factor(fine, T_ref, *args)
    return T, min_speeds(T, h, v0, a0, v1, a1) < -1e-9 * (1.0 + v0 + v1)


#: samples per interval of the final no-reversal test (the duration search's 9 missed a
#: dip of ~15 % of an interval's time into rest on c-rand6-scales)
SPEED_SAMPLES = 65


def min_speeds(T, h, v0, a0, v1, a1) -> np.ndarray:
    """The least ds/dt of each interval's quintic, on SPEED_SAMPLES points of its time."""
    c3, c4, c5 = quintic_coefficients(T, h, v0, a0, v1, a1)
    tau = T[:, None] * np.linspace(0.0, 1.0, SPEED_SAMPLES)
    speed = (v0[:, None] + tau * (a0[:, None] + tau * (3.0 * c3[:, None] + tau * (
        4.0 * c4[:, None] + tau * 5.0 * c5[:, None]))))
    return np.min(speed, axis=1)


#: rounds of `secant_accelerations` before a profile is built as it is (a guard against
#: a new reversal next to a changed node; how many rounds the corpus needs is not measured,
#: the fast corpus has no fallback or violation left from a reversal)
REVERSAL_ROUNDS = 3


def secant_accelerations(h: np.ndarray, q: np.ndarray, a: np.ndarray, reverses: np.ndarray,
                         changed: np.ndarray | None = None) -> np.ndarray:
    """The node accelerations with the free nodes (not the first or last, not at rest) of
    each reversing interval set to that interval's secant (q_i+1 - q_i) / (2 h), the
    constant path acceleration of q linear in s, which a quartic follows without
    reversing; a node shared by two reversing intervals takes the smaller magnitude.

    Why: at a sharp dip of q (a near-stall between nodes, or the last node before a rest
    end after a hard braking) the central slope of q at the node belongs to the steep side,
    and the interval on the flat side cannot keep ds/dt >= 0 with it: the quintic reverses
    by ~1e-4 mm, which the sampler holds (s non-decreasing, `lookahead.sampling`) and the
    checker sees as a jerk spike (measured: 2.6x jmax on c-rand6-scales, 5x on
    c-fourier-xc, both passing the analytic check, which follows the reversal).

    changed: per node, whether an earlier round set it (updated in place); such a node
    asked now for a secant of the other sign takes a = 0 (`profile_from_grid`'s rounds)."""
    a = a.copy()
    secant = np.diff(q) / (2.0 * h)
    pick = np.full(a.size, np.inf)
    for j in np.nonzero(reverses)[0]:
        for node in (j, j + 1):
            if 0 < node < a.size - 1 and q[node] > 0.0 and abs(secant[j]) < abs(pick[node]):
                pick[node] = secant[j]
    chosen = np.isfinite(pick)
    if changed is not None:
        # a node set in an earlier round whose other interval now reverses: the two
        # secants have opposite signs at a dip of q (the round-to-round swap left one
        # side reversing, OSQP's near-stop on the pocketing program), and a = 0, the
        # acceleration of a minimum, lies between them; same signs: the smaller
        flip = chosen & changed & (np.sign(pick) != np.sign(a))
        pick[flip] = 0.0
        changed |= chosen
    a[chosen] = pick[chosen]
    return a


def profile_from_grid(
    s: np.ndarray, q: np.ndarray, a_start: float, a_end: float | None
) -> FeedProfile:
    """The C2 quintic profile through the grid states (s_i, sqrt(q_i), q'_i / 2)."""
    q = np.maximum(q, 0.0)
    v = np.sqrt(q)
    a = node_accelerations(s, q, a_start, a_end)
    h = np.diff(s)
    T, reverses = durations_and_reversals(h, v, a)
    changed = np.zeros(a.size, dtype=bool)
    for _ in range(REVERSAL_ROUNDS):
        if not np.any(reverses):
            break
        a = secant_accelerations(h, q, a, reverses, changed)
        T, reverses = durations_and_reversals(h, v, a)
    if reverses[0] and v[0] > 0.0:
        # the start state's acceleration is fixed (no secant for node 0): a braking start
        # whose quintic dips below 0 before the next node reverses, and the sampler's hold
        # makes that a jerk spike the analytic check does not see (w-hoop-R40 from 2.56
        # mm/s at -324 mm/s^2: 10.6x jmax); the plan is refused (`lp.handover` follows)
        raise PlanningError(f"lp: the feed reverses after the start (v={v[0]:.6g}, "
                            f"a={a[0]:.6g}): the grid cannot follow its braking")
    c3, c4, c5 = quintic_coefficients(T, h, v[:-1], a[:-1], v[1:], a[1:])
    coeffs = np.stack([c5, c4, c3, 0.5 * a[:-1], v[:-1], s[:-1]])
    t = np.concatenate([[0.0], np.cumsum(T)])
    return FeedProfile(PPoly(coeffs, t, extrapolate=False))


def grid_time(s: np.ndarray, q: np.ndarray) -> float:
    """Travel time of q linear in s: sum 2 h / (sqrt(q_i) + sqrt(q_i+1)) (s)."""
    v = np.sqrt(np.maximum(q, 0.0))
    vsum = v[:-1] + v[1:]
    with np.errstate(divide="ignore"):
        return float(np.sum(np.where(vsum > 0, 2.0 * np.diff(s) / vsum, np.inf)))


