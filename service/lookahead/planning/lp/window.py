"""The windowed LP: plan a long path window by window, as the streaming service does.

Each window is a plain `Planner.plan(PlanRequest)` call on [s_c, s_c + W] that starts in
the committed state (s, v, a) and ends at rest, so that whatever has been published can
always be brought to rest within the limits. Only the part up to W minus one braking
distance is committed (the rest of the window is re-planned by the next one, with more
path in view); W >= 3 braking distances loses nothing against planning the whole path.
If a window fails, the previous window's stopping tail is used (the machine comes to
rest at that window's end) and planning restarts from rest there.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import PPoly

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import (
    FeedProfile,
    PathState,
    PlanningError,
    PlanRequest,
    PlanResult,
)
from lookahead.planning.lp.envelope import braking_distance, path_limits
from lookahead.planning.lp.planner import LPPlanner
from lookahead.planning.lp.rows import GridGeometry, velocity_caps
from lookahead.planning.profile_ops import concatenate, slice_profile


def path_braking_distance(path: Path, limits: AxisLimits, s0: float = 0.0,
                          s1: float | None = None, samples: int = 2000) -> float:
    """Braking distance from the fastest feed the velocity limits allow on [s0, s1]."""
    s1 = path.length if s1 is None else s1
    geo = GridGeometry.sample(path, np.linspace(s0, s1, samples))
    v = float(np.sqrt(np.max(velocity_caps(geo, limits.vmax))))
    a_max, j_max = path_limits(path, limits)
    return braking_distance(v, a_max, j_max)


@dataclass
class WindowStep:
    """One window: where it started, what it committed, how long it took."""

    s_start: float
    s_window_end: float
    s_commit: float
    compute_s: float
    fallback: bool


class WindowedLP:
    """Windowed LP driver. window_s: window length W in path units (None: `n_braking`
    braking distances from the fastest feed on the path). brake_factor: see
    `window_braking`."""

    name = "lp-windowed"

    def __init__(self, planner: LPPlanner | None = None, window_s: float | None = None,
                 n_braking: float = 3.0, brake_factor: float | None = None) -> None:
        self.brake_factor = brake_factor
        self.planner = planner or LPPlanner()
        self.window_s = window_s
        self.n_braking = n_braking

    def window_braking(self, result: PlanResult, brake: float,
                       a_j: tuple[float, float]) -> float:
        """The stretch before the window's end left uncommitted (path units): `brake_factor`
        braking distances from the fastest feed the window's plan reaches, at the path
        acceleration and jerk of the planner's stop envelope (the stop at the window's end
        reaches back no further), at most `brake` (from the path's top feed).

        The path's top feed (~1350 mm/s on the winders, where the mandrel alone moves)
        is rarely reached: the planned feed is ~700 mm/s, whose braking distance is a
        third, so a window commits ~90 % of its length instead of ~67 %."""
        if self.brake_factor is None:
            return brake
        q = result.info.get("grid_q")
        if q is None:
            pp = result.profile.s_of_t
            v_peak = float(np.max(pp.derivative()(pp.x)))
        else:
            v_peak = float(np.sqrt(np.max(q)))
        lp = self.planner
        a_max = a_j[0] * lp.margins[1]
        j_max = a_j[1] * lp.envelope_jerk * lp.margins[2] * lp.envelope_margin
        return min(brake, self.brake_factor * braking_distance(v_peak, a_max, j_max))

    def commit_point(self, result: PlanResult, s_window_end: float, brake: float) -> float:
        """Time (from the window's start) of the last grid node at or before
        s_window_end - brake; at least the first node after the start."""
        pp = result.profile.s_of_t
        s_nodes = pp(pp.x)
        k = int(np.searchsorted(s_nodes, s_window_end - brake, side="right")) - 1
        k = min(max(k, 1), pp.x.size - 1)
        return float(pp.x[k] - pp.x[0])

    def plan(self, request: PlanRequest) -> PlanResult:
        """Plan [start.s, s_end] window by window and stitch the committed parts."""
        t0 = time.perf_counter()
        brake = path_braking_distance(request.path, request.limits, request.start.s,
                                      request.s_end)
        W = self.window_s or self.n_braking * brake
        brake = min(brake, W / self.n_braking)
        a_j = path_limits(request.path, request.limits)
        state, pieces, steps = request.start, [], []
        previous: PlanResult | None = None
        while True:
            s_we = min(state.s + W, request.s_end)
            last = s_we >= request.s_end - 1e-9
            window = replace(request, start=state, s_end=s_we,
                             v_end=request.v_end if last else 0.0)
            tw = time.perf_counter()
            try:
                res = self.planner.plan(window)
                fallback = False
            except PlanningError:
                if previous is None:
                    raise
                res, fallback = previous, True
            if last and not fallback:
                pieces.append(res.profile)
                steps.append(WindowStep(state.s, s_we, s_we, time.perf_counter() - tw, False))
                break
            if fallback:
                # the previous window's stopping tail: run it out to rest, restart from there
                pieces.append(res.profile)
                end = res.profile.state_at(res.profile.duration)
                state = PathState(end.s, 0.0, 0.0)
                steps.append(WindowStep(state.s, state.s, state.s, time.perf_counter() - tw,
                                        True))
                previous = None
                continue
            t_commit = self.commit_point(res, s_we, self.window_braking(res, brake, a_j))
            head = slice_profile(res.profile, 0.0, t_commit)
            tail = FeedProfile(PPoly(res.profile.s_of_t.c[:, head.s_of_t.c.shape[1]:],
                                     res.profile.s_of_t.x[head.s_of_t.c.shape[1]:],
                                     extrapolate=False))
            pieces.append(head)
            state = res.profile.state_at(t_commit)
            steps.append(WindowStep(window.start.s, s_we, state.s, time.perf_counter() - tw,
                                    False))
            previous = PlanResult(tail, res.method, res.compute_s, res.info)
        profile = concatenate(pieces)
        info = {
            "window_s": W,
            "braking_s": brake,
            "windows": len(steps),
            "fallbacks": sum(st.fallback for st in steps),
            "steps": steps,
            "max_window_compute_s": max(st.compute_s for st in steps),
        }
        return PlanResult(profile, self.name, time.perf_counter() - t0, info)

    plan_whole = plan
