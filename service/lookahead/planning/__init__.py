"""Feed planning along a path: one interface, three methods (heuristic, lp, nlp)."""

from lookahead.planning.base import (
    FeedCap,
    FeedProfile,
    PathState,
    Planner,
    PlanningError,
    PlanRequest,
    PlanResult,
)

__all__ = [
    "FeedCap",
    "FeedProfile",
    "PathState",
    "PlanRequest",
    "PlanResult",
    "Planner",
    "PlanningError",
]
