"""A corpus path's first window planned as the engine plans it, and replan requests from
its samples (the service replans from the state of its last published sample): shared by
the replan tests of the heuristic and the LP."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from bench.corpus import load_corpus
from bench.corpus.base import CorpusPath

from lookahead.geometry.base import Path
from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedCap, PathState, PlanRequest
from lookahead.stream.engine import horizon_length
from lookahead.stream.planners import make_planner
from lookahead.stream.plans import CommittedPlan


@dataclass(frozen=True)
class FirstWindow:
    """The engine's first window of `corpus` (limits with the configured margin, window
    length in path units, the feed cap) and its plan anchored at sample 0."""

    corpus: CorpusPath
    path: Path
    limits: AxisLimits
    window: float
    feed_cap: FeedCap | None
    dt: float
    request: PlanRequest
    plan: CommittedPlan

    @property
    def samples(self) -> int:
        """Whole samples of the plan's motion."""
        return int(self.plan.profile.duration / self.dt)

    def replan(self, k: int) -> tuple[PlanRequest, np.ndarray]:
        """The request of a replan from sample k of the plan, one window on, and the
        published samples k-2..k that the engine checks its continuity against."""
        st = self.plan.state(k, self.dt)
        tail = self.plan.samples(max(k - 2, 0), min(k, 2) + 1, self.dt).pos
        return PlanRequest(self.path, self.limits, st, min(self.path.length,
                           st.s + self.window), 0.0, self.feed_cap, self.dt), tail


def first_window(pattern: str, method: str = "heuristic") -> FirstWindow:
    """The first window of the fast corpus's path named `pattern`, planned by `method`."""
    p = load_corpus("fast", pattern=pattern)[0]
    cfg, m = p.config, p.config.machine
    path = p.path()
    cap = p.geometry().feed_cap()
    lim = m.limits.scaled(cfg.planner.margin)
    window = horizon_length(lim, np.asarray(m.path_scale, float), cfg.planner.horizon_s)
    request = PlanRequest(path, lim, PathState(0.0), min(path.length, window), 0.0, cap,
                          m.dt)
    first = make_planner(method).plan(request)
    return FirstWindow(p, path, lim, window, cap, m.dt, request,
                       CommittedPlan.anchor(path, first, 0, m.dt))
