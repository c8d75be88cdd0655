"""The heuristic feed planner (paper 3.2, with free junction states) as a package.

Modules, each importing only the ones above it:

- `scurve`: 1-DOF Ruckig S-curves along s, compatibility distances, cutting phases.
- `profile_build`: constant-jerk phases -> `FeedProfile`; path state at given s.
- `path_limits`: geometry on a grid of cells, the feed-limit curve, planning segments and
  their budgets.
- `split`: segments split where their constant cap loses time under the limit curve.
- `levels`: acceleration budgets per segment that depend on the feed.
- `rise`: the fastest rise within a segment, under one budget or under feed levels.
- `verify`: the planner's own check of the axis terms at the grid points (and corners).
- `scan`: forward/backward jerk-limited scans, free junction states, the segment chain.
- `zero_junctions`: the paper's junctions with path acceleration 0 (the fallback).
- `brake`: braking a start state that is above the limits.
- `continuation`: a replan kept on the last plan up to its next cruise state.
- `planner`: `HeuristicPlanner` (rounds of chain, verification and repair).
"""

from lookahead.planning.heuristic.planner import HeuristicPlanner, plan_rest_to_rest

__all__ = ["HeuristicPlanner", "plan_rest_to_rest"]
