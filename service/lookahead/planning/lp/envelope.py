"""Jerk-limited start/stop envelopes for the feed LP.

The LP's jerk rows vanish where q = 0 (jerk = sqrt(q) L), so from rest it would step the
path acceleration from 0 to its maximum. The cure is an upper bound on q near every point
where the state is prescribed: the fastest feed a 1-DOF S-curve (path jerk <= J, path
acceleration <= A) can reach at distance d from that state. Time-reversed, the same bound
holds before a stop.
"""

from __future__ import annotations

import numpy as np

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits


def tangent_limits(tangent: np.ndarray, limits: AxisLimits) -> tuple[float, float]:
    """Path acceleration and jerk (path units / s^2, / s^3) at low feed along a tangent
    whose axis components are at most `tangent` (|x'_k|, shape (naxes,)): the axis
    acceleration and jerk there are x'_k a and x'_k j, so min_k amax_k / |x'_k| and
    min_k jmax_k / |x'_k| (an axis with x'_k = 0 does not bound them)."""
    with np.errstate(divide="ignore"):
        return float(np.min(limits.amax / tangent)), float(np.min(limits.jmax / tangent))


def path_limits(path: Path, limits: AxisLimits) -> tuple[float, float]:
    """Conservative `tangent_limits`: any axis may carry the whole tangent,
    |x'_k| <= 1/path_scale_k."""
    return tangent_limits(1.0 / np.asarray(path.path_scale, dtype=float), limits)


#: `envelope_limits`: an axis whose tangent share |x'_k| path_scale_k stays below this over
#: the window counts at its own largest tangent there, not at the whole tangent ...
ENVELOPE_AXIS_SHARE = 0.01
#: ... and only where that lifts the path-level limits more than this factor; below it,
#: `path_limits`'s conservatism is the LP's margin near rest. Measured: the window's
#: tangents for every axis changed 45 of 63 corpus paths by -6 % .. +24 % (steeper starts
#: needing repairs on short paths: c-short-winder-0p8mm 0.131 -> 0.163 s); the share rule
#: alone lifted the winder3 lock program's envelope 6.7x (its delivery axis B at 0.9 % of
#: the tangent), and LP replans from the braking into its lock failed on 1 of 61 states
#: (test_lp_feasibility). c-rand6's raw-metric path needs 1e5 (U's limits against Z's)
ENVELOPE_LIFT = 10.0


def envelope_limits(tangents: np.ndarray, path_scale: np.ndarray, limits: AxisLimits
                    ) -> tuple[float, float]:
    """Path acceleration and jerk (path units / s^2, / s^3) for the LP's start/stop
    envelopes that do not follow a rest's own tangents (`rest_envelope`: moving starts and
    ends, rests in bends) over a window whose nodes have the tangents `tangents` (shape
    (n, naxes), x'_k): `path_limits` (each axis may carry the whole tangent, |x'_k| <= 1 /
    path_scale_k), unless the axes that barely move there (share below
    ENVELOPE_AXIS_SHARE), counted at their largest |x'_k| instead, lift a limit more than
    ENVELOPE_LIFT times. Why: a path whose small-limit axes barely move (c-rand6 in the raw
    mm metric: U's limits 1e-6 of Z's) got U's limits as the path's, and the envelopes held
    the feed to ~40 where the caps allow ~2000 (a plan 99x the v+a bound)."""
    xmax = 1.0 / np.asarray(path_scale, dtype=float)
    along = np.max(np.abs(np.asarray(tangents, dtype=float)), axis=0)
    lifted = tangent_limits(np.where(along < ENVELOPE_AXIS_SHARE * xmax, along, xmax), limits)
    worst = tangent_limits(xmax, limits)
    return tuple(new if new > ENVELOPE_LIFT * old else old  # type: ignore[return-value]
                 for new, old in zip(lifted, worst, strict=True))


def braking_distance(v: float, a_max: float, j_max: float) -> float:
    """Distance to stop from feed v at zero acceleration with a jerk-limited S-curve
    (path units): v/2 (v/A + A/J) if v >= A^2/J, else v sqrt(v/J)."""
    if v >= a_max**2 / j_max:
        return 0.5 * v * (v / a_max + a_max / j_max)
    return v * float(np.sqrt(v / j_max))


def reachable_q(d: np.ndarray, v0: float, a0: float, J: float, A: float,
                table: int = 1025, newton: int = 3) -> np.ndarray:
    """The largest q = v^2 reachable at distance d >= 0 from state (v0, a0) with jerk <= J
    and acceleration <= A: jerk J until the acceleration is A, then acceleration A.

    Hand-written (one S-curve, no library covers it): the acceleration phase is closed
    form; in the jerk phase t(d) is read off a table of the cubic distance over the times
    the nodes need, then polished by `newton` Newton steps (a 60-step vectorized
    bisection cost ~2 ms per call in numpy overhead, a tenth of a window's planning).
    """
    d = np.asarray(d, dtype=float)
    a0 = min(a0, A)
    t1 = (A - a0) / J

    def dist(t):
        return v0 * t + 0.5 * a0 * t**2 + J * t**3 / 6.0

    def speed(t):
        return v0 + a0 * t + 0.5 * J * t**2

    q = max(speed(t1), 0.0) ** 2 + 2.0 * A * np.maximum(d - dist(t1), 0.0)
    k = d <= dist(t1)
    if np.any(k):
        dk = d[k]
        # dist >= J t^3 / 6 when v0, a0 >= 0; the doubling covers the other states
        t_hi = min(t1, float(np.cbrt(6.0 * dk.max() / J)))
        while t_hi < t1 and dist(t_hi) < dk.max():
            t_hi = min(2.0 * t_hi, t1)
        tt = np.linspace(0.0, t_hi, table)
        t = np.interp(dk, np.maximum.accumulate(dist(tt)), tt)
        for _ in range(newton):
            sp = speed(t)
            step = np.where(sp > 0.0, (dist(t) - dk) / np.where(sp > 0.0, sp, 1.0), 0.0)
            t = np.clip(t - step, 0.0, t_hi)
        q[k] = np.maximum(speed(t), 0.0) ** 2
    return q


def braking_q(d: np.ndarray, v0: float, a0: float, J: float, A: float,
              table: int = 4097) -> np.ndarray:
    """The smallest q = v^2 at distance d >= 0 from state (v0, a0) (path units, /s, /s^2)
    along the hardest jerk-limited braking: jerk -J until the acceleration is -A, then
    acceleration -A until the feed is 0; q = 0 beyond. Every motion from that state with
    path jerk >= -J and acceleration >= -A has at least this q at every d (it is never
    slower at equal time, nor at equal distance). Hand-written like `reachable_q`: closed
    form in t, read off a table at the distances (no library gives q(d) of an S-curve)."""
    d = np.asarray(d, dtype=float)
    a0 = max(a0, -A)
    t1 = (a0 + A) / J  # jerk phase
    v1 = v0 + a0 * t1 - 0.5 * J * t1**2
    # the feed vanishes in the jerk phase, or at the end of the constant -A phase
    t_end = (a0 + np.sqrt(a0**2 + 2.0 * J * v0)) / J if v1 <= 0.0 else t1 + v1 / A
    t = np.linspace(0.0, t_end, table)
    jt = np.minimum(t, t1)
    v = v0 + a0 * jt - 0.5 * J * jt**2 - A * np.maximum(t - t1, 0.0)
    dist_j = v0 * jt + 0.5 * a0 * jt**2 - J * jt**3 / 6.0
    tc = np.maximum(t - t1, 0.0)
    dist = dist_j + np.where(t > t1, v1 * tc - 0.5 * A * tc**2, 0.0)
    v = np.maximum(v, 0.0)
    dist = np.maximum.accumulate(dist)
    q = np.interp(d, dist, v**2, right=0.0)
    return q


def rest_q(d: np.ndarray, J: np.ndarray, A: np.ndarray) -> np.ndarray:
    """The largest q = v^2 an S-curve from rest reaches at distance d >= 0 with jerk <= J
    and acceleration <= A (path units; d, J, A broadcast): jerk J for t <= A/J
    (d = J t^3 / 6, v = J t^2 / 2), then acceleration A. Closed form: `reachable_q` with
    v0 = a0 = 0, for limits that vary with d."""
    d, J, A = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (d, J, A)))
    d1 = A**3 / (6.0 * J**2)  # where the jerk phase ends
    v1 = A**2 / (2.0 * J)
    t = np.cbrt(6.0 * np.minimum(d, d1) / J)
    return np.where(d <= d1, (0.5 * J * t**2) ** 2, v1**2 + 2.0 * A * (d - d1))


def _rest_bound(s: np.ndarray, centre: float, tangents: np.ndarray, limits: AxisLimits,
                jerk_scale: np.ndarray, acc_scale: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """`local_rest_q`'s bound q per node and the path acceleration limit A it used there."""
    d = np.abs(s - centre)
    order = np.argsort(d, kind="stable")
    xmax = np.maximum.accumulate(np.abs(tangents[order]), axis=0)
    with np.errstate(divide="ignore"):
        J = np.min(limits.jmax / xmax, axis=1) * np.minimum.accumulate(jerk_scale[order])
        A = np.min(limits.amax / xmax, axis=1) * np.minimum.accumulate(acc_scale[order])
    q = np.empty_like(d)
    q[order] = rest_q(d[order], J, A)
    a = np.empty_like(d)
    a[order] = A
    return q, a


def local_rest_q(s: np.ndarray, centre: float, tangents: np.ndarray, limits: AxisLimits,
                 jerk_scale: np.ndarray, acc_scale: np.ndarray) -> np.ndarray:
    """The S-curve bound on q (path units^2 / s^2) at the nodes s around a rest at
    `centre`, at the path-level limits of the tangents on the way: at distance d, jerk
    min_k jmax_k / max |x'_k| and acceleration min_k amax_k / max |x'_k| over the nodes
    within d of the centre (times the node factors `jerk_scale`, `acc_scale`, their least
    within d). Never below the bound at `path_limits` (|x'_k| <= 1 / path_scale_k); near
    a rest only the tangent there matters (the curvature terms vanish with the feed), and
    the worst tangent of the whole path made the bound up to 2.6x too slow (a stroke's
    end, where only C moves: 51300 against 19600 mm/s^3)."""
    return _rest_bound(s, centre, tangents, limits, jerk_scale, acc_scale)[0]


#: `rest_envelope`: the share of an axis's acceleration and jerk limits that the curvature
#: terms may take at the local bound's feeds for the tangent alone to bound the motion
#: near a rest. Trades the envelopes' speed on straight approaches against bends near a
#: rest, where the tangent-only bound lets the coupling 3 |x_ss| v a and |x_sss| v^3 take
#: the jerk over its limit (the lock of a fiberpath-style turnaround, X reversing within
#: 2 mm of path while A goes on: repairs stuck at +32 % jerk without the rule, planned at
#: 0.1, 0.25 and 0.5). At 0.1 on the 64 non-long corpus paths: lp 27 faster, 2 slower
#: (bench/results/corpus_rest_envelopes.json against ..._before.json); 0.03 and 0.25
#: plan the fast subset as 0.1 does to 0.61 % (1-3 paths of 16 differ,
#: corpus_rest_share_0p03.json, corpus_rest_share_0p25.json). 0.25 since stop 45, on all
#: 64 (corpus_rest_share_0p25_all.json against corpus_stop45.json): 0 failures, lp 4
#: faster (c-rand3-xyz-2000pts -3.3 %, n-heart -2.5 %: its start and end, 1.028 -> 1.002x
#: the fine-grid reference), 0 slower; engine-lp 7 faster, 1 slower (+0.30 %, hel25)
REST_CURVATURE_SHARE = 0.25


#: `lowered_rest_envelope`: the share of a tangent limit that must be left beside the
#: curvature terms at every node where the bound matters (below: a tight bend at the rest,
#: the conservative envelope; the lowered limits are never below it). Trades how tight a
#: bend may be against how far its limits may be lowered: c-rand6-scales-raw's whole-job
#: LP 11.18 / 10.70 / 10.65 s at 0.1 / 0.25 / 0.5 (12.12 s without; stop 50) ...
CURVED_REST_FLOOR = 0.25
#: ... and how far (a factor on q) the lowered bound must lift the conservative envelope
#: somewhere below the top feed to replace it. Trades the start out of a rest in a bend
#: against the repairs a steeper start needs: on cam-fp-hel45-D30 a start lifted a little
#: took one repair more whose tightening cost the first window 0.34 s (windowed +1.5 %,
#: 1.0216x its whole job) at 1 (no gate). Measured on 6 changed corpus paths at 2 and 4
#: (stop 50): 2 kept every gain but the one that cost, 4 only c-rand6-scales-raw's. At
#: 0.25 and 2 on the 64 non-long paths (bench/results/corpus_curved_rest_{before,after}
#: .json): lp 4 faster (c-rand6-scales-raw -11.7 %, c-fourier-xc -1.4 %, cam-style-R100
#: -1.3 %, c-rand5 -0.6 %), engine-lp 3 faster, none slower, 0 failures
CURVED_REST_LIFT = 2.0


def _curvature_room(q: np.ndarray, a: np.ndarray, d1: np.ndarray, d2: np.ndarray,
                    d3: np.ndarray, limits: AxisLimits) -> tuple[np.ndarray, np.ndarray]:
    """Per node, the shares of the tangent-only path acceleration and jerk limits
    (min_k amax_k / |x_s,k|, min_k jmax_k / |x_s,k|) left beside the curvature terms at
    feed v = sqrt(q) and path acceleration a: min_k (amax_k - |x_ss,k| v^2) / |x_s,k| and
    min_k (jmax_k - |x_sss,k| v^3 - 3 |x_ss,k| v a) / |x_s,k| over them (1 where no axis
    moves along the tangent; negative where the terms alone exceed a limit)."""
    v = np.sqrt(q)[:, None]
    x1, x2, x3 = np.abs(d1), np.abs(d2), np.abs(d3)
    with np.errstate(divide="ignore", invalid="ignore"):
        a_tan = np.min(limits.amax / x1, axis=1)
        j_tan = np.min(limits.jmax / x1, axis=1)
        acc = np.min((limits.amax - x2 * v**2) / x1, axis=1) / a_tan
        jerk = np.min((limits.jmax - x3 * v**3 - 3.0 * x2 * v * a[:, None]) / x1,
                      axis=1) / j_tan
    return np.where(np.isfinite(a_tan), acc, 1.0), np.where(np.isfinite(j_tan), jerk, 1.0)


def rest_envelope(s: np.ndarray, centre: float, d1: np.ndarray, d2: np.ndarray,
                  d3: np.ndarray, limits: AxisLimits, jerk_scale: np.ndarray,
                  acc_scale: np.ndarray, q_top: float) -> np.ndarray | None:
    """`local_rest_q` around a rest at `centre` where the tangent bounds the motion there:
    at the bound's own feeds v (nodes where q < q_top, the highest q that matters), the
    curvature terms |x_ss| v^2 and |x_sss| v^3 + 3 |x_ss| v A (A: the bound's path
    acceleration) take at most REST_CURVATURE_SHARE of every axis's amax and jmax. None
    where they take more (a bend near the rest): the caller then tries
    `lowered_rest_envelope`, else keeps the conservative envelope (`path_limits` /
    `envelope_limits`), which leaves them room; also where the bound is undefined (NaN: a
    node whose tangent vanishes, a pchip knot where the fit stops in every axis)."""
    q, a = _rest_bound(s, centre, d1, limits, jerk_scale, acc_scale)
    if np.any(np.isnan(q)):
        return None
    near = q < q_top
    if np.any(near):
        v = np.sqrt(q[near])[:, None]
        x2, x3 = np.abs(d2[near]), np.abs(d3[near])
        acc = np.max(x2 * v**2 / limits.amax)
        jerk = np.max((x3 * v**3 + 3.0 * x2 * v * a[near][:, None]) / limits.jmax)
        if max(acc, jerk) > REST_CURVATURE_SHARE:
            return None
    return q


def lowered_rest_envelope(s: np.ndarray, centre: float, d1: np.ndarray, d2: np.ndarray,
                          d3: np.ndarray, limits: AxisLimits, jerk_scale: np.ndarray,
                          acc_scale: np.ndarray, q_top: float, conservative: np.ndarray
                          ) -> np.ndarray | None:
    """For a rest in a bend (`rest_envelope` None): `local_rest_q` with each node's limits
    lowered by what the curvature terms take at the tangent-only bound's feeds
    (`_curvature_room`; one step, conservative: the lowered bound's feeds, and so its
    terms, are smaller), where that leaves at least CURVED_REST_FLOOR of the tangent's
    limits at every node where q < q_top and lifts the `conservative` envelope (q per
    node) more than CURVED_REST_LIFT times at a node where that is below q_top; else None.

    Why: c-rand6-scales-raw rests in bends whose axes allow ~14,000 mm/s^2 along the
    tangent, and the conservative envelope held its starts to 960 mm/s^2 (the window's
    worst tangent)."""
    q, a = _rest_bound(s, centre, d1, limits, jerk_scale, acc_scale)
    if np.any(np.isnan(q)):
        return None
    acc_room, jerk_room = _curvature_room(np.minimum(q, q_top), a, d1, d2, d3, limits)
    near = q < q_top
    if np.any(near) and min(np.min(acc_room[near]), np.min(jerk_room[near])) < \
            CURVED_REST_FLOOR:
        return None
    bound = _rest_bound(s, centre, d1, limits,
                        jerk_scale * np.maximum(jerk_room, CURVED_REST_FLOOR),
                        acc_scale * np.maximum(acc_room, CURVED_REST_FLOOR))[0]
    below = conservative < q_top
    if np.any(np.isnan(bound)) or not np.any(bound[below] > CURVED_REST_LIFT *
                                             conservative[below]):
        return None
    return bound
