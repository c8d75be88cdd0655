"""The planner interface shared by the heuristic, LP and NLP methods.

Frames and units: s is arc length along a `Path` in the path metric (path units, mm for
the winder), t is seconds from the start of the profile. A plan covers [start.s, s_end]
of the path, starts in an arbitrary state (the service replans mid-motion) and ends at
rest (v_end = 0) or at a given feed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.interpolate import PPoly

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits


class PlanningError(RuntimeError):
    """A planner could not produce a profile that satisfies the request."""


@dataclass(frozen=True)
class PathState:
    """State along the path: position s, feed ds/dt, path acceleration d2s/dt2."""

    s: float
    v: float = 0.0
    a: float = 0.0


@dataclass(frozen=True)
class FeedCap:
    """A piecewise-constant cap on the feed over s: values[i] on [s_breaks[i], s_breaks[i+1]).

    s_breaks has len(values) + 1 entries, increasing; values > 0 (path units per s).
    """

    s_breaks: np.ndarray
    values: np.ndarray

    def at(self, s: np.ndarray) -> np.ndarray:
        """The cap at each s (the last interval is closed on the right)."""
        s = np.asarray(s, dtype=float)
        idx = np.searchsorted(self.s_breaks, s, side="right") - 1
        idx = np.clip(idx, 0, len(self.values) - 1)
        return self.values[idx]

    def changes(self) -> np.ndarray:
        """The breaks (arc lengths) where the cap changes value."""
        return self.s_breaks[1:-1][np.diff(self.values) != 0]

    def at_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """The cap a planner's node must keep (nodes: increasing arc lengths): the
        smallest cap over the grid intervals on either side of it. A node just before a
        drop of the cap, or just after a rise, bounds a feed that the interval beside it
        carries into the lower cap; with the breaks themselves as nodes
        (`lp.grid.with_breaks`) only the node at a break is lowered, to the smaller of
        its two sides, and every interval lies under one cap."""
        nodes = np.asarray(nodes, dtype=float)
        cap = self.at(nodes)
        if nodes.size < 2:
            return cap
        b, v, last = self.s_breaks, self.values, len(self.values) - 1
        # the caps over each open interval (nodes[i], nodes[i+1]): regions lo .. hi
        lo = np.clip(np.searchsorted(b, nodes[:-1], side="right") - 1, 0, last)
        hi = np.clip(np.searchsorted(b, nodes[1:], side="left") - 1, 0, last)
        span = np.minimum(v[lo], v[np.maximum(hi, lo)])
        for i in np.nonzero(hi > lo + 1)[0]:  # an interval across several breaks (rare)
            span[i] = np.min(v[lo[i]:hi[i] + 1])
        cap[:-1] = np.minimum(cap[:-1], span)
        cap[1:] = np.minimum(cap[1:], span)
        return cap


@dataclass(frozen=True)
class FeedProfile:
    """The feed along the path as s(t): a scipy PPoly in t (seconds from the profile's
    start) giving absolute arc length s, of degree >= 3 and C2 in t, so that path
    velocity and acceleration are continuous and path jerk is bounded."""

    s_of_t: PPoly

    @property
    def duration(self) -> float:
        return float(self.s_of_t.x[-1] - self.s_of_t.x[0])

    def at(self, t: np.ndarray) -> np.ndarray:
        """Shape (4, len(t)): s, ds/dt, d2s/dt2, d3s/dt3 at times t (clipped to the profile)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        t = t + self.s_of_t.x[0]
        return np.stack([self.s_of_t(t, nu) for nu in range(4)])

    def state_at(self, t: float) -> PathState:
        s, v, a, _ = self.at(np.array([t]))[:, 0]
        return PathState(float(s), float(v), float(a))


@dataclass(frozen=True)
class PlanRequest:
    """What to plan: the stretch [start.s, s_end] of `path` under `limits`.

    feed_cap: optional cap on the feed (segment `feed` fields, override).
    dt: the sample time the result will be sampled at (for C1-knot feed caps).
    v_end: feed at s_end, reached with path acceleration 0 (so that a plan from there can
    continue); 0 means come to rest exactly at s_end.
    """

    path: Path
    limits: AxisLimits
    start: PathState
    s_end: float
    v_end: float = 0.0
    feed_cap: FeedCap | None = None
    dt: float = 0.001


@dataclass(frozen=True)
class PlanResult:
    """A planned feed profile and what it cost."""

    profile: FeedProfile
    method: str
    compute_s: float
    info: dict = field(default_factory=dict)


class Planner(Protocol):
    """A feed planner. Implementations: heuristic, lp, nlp."""

    name: str

    def plan(self, request: PlanRequest) -> PlanResult:
        """Plan the feed; raise PlanningError if no valid profile is found."""
        ...
