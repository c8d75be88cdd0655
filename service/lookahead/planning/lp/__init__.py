"""The LP feed planner (the paper's 3.3, Fan et al.) as a package.

Modules, each importing only the ones above it:

- `grid`: the s-grid (uniform, graded towards rest points).
- `rows`: the LP's variables q = (ds/dt)^2 at the nodes, its linear rows (velocity caps,
  acceleration, linearized jerk, jerk change, end slopes) and the per-node `Tightening`.
- `profile`: grid values -> C2 quintic feed profile s(t); grid travel time.
- `envelope`: jerk-limited start/stop S-curve bounds on q, braking distances.
- `release`: a braking start at low feed released in closed form before the LP.
- `solve`: the scaled LP and its backends (HiGHS, OSQP).
- `seam`: where a replan continues the last plan.
- `handover`: a moving start the LP cannot follow, handed over through the heuristic's
  transient to a state of zero path acceleration.
- `rest_stretches`: the stretches between two rest points of a plan, which another
  planner's faster plan may replace, and the replans that start on such a plan.
- `planner`: `LPPlanner` (grid, LP passes, relaxation, check/repair loop).
- `window`: `WindowedLP`, the whole-job driver that plans window by window.

The names below are loaded on first use (PEP 562), so that importing one module (e.g.
`lp.rows` from `planning.sampled_check`, which `planner` imports) never runs the others.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "LPPlanner": "planner",
    "default_grid_step": "planner",
    "Tightening": "rows",
    "WindowedLP": "window",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{module}"), name)
