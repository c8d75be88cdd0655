"""The planner the service runs, by configured method name."""

from __future__ import annotations

from lookahead.planning.base import Planner


def make_planner(method: str) -> Planner:
    """A planner for `method` ('heuristic' or 'lp') that plans to exactly the limits in its
    requests (the engine applies the configured margin and the override itself)."""
    if method == "heuristic":
        from lookahead.planning.heuristic import HeuristicPlanner

        return HeuristicPlanner(margin=1.0)
    if method == "lp":
        from lookahead.planning.lp import LPPlanner

        return LPPlanner()
    raise ValueError(f"planner.method: unknown method {method!r} (known: heuristic, lp)")
