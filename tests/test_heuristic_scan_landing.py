"""The backward scan keeps free junction states where its restarts at caps meet a falling
scan (issue 14). On the butterfly the scan restarts at a cap below a near-cusp, and the
forward rises from there, accelerating as hard as they may, met the deceleration into the
next cusp with too much acceleration to turn within one segment; the scan then fell back to
the zero-acceleration junction feeds, which cascaded forward over whole stretches (a third
of all junctions; the plan held the feed far below the limit curve there). Now the rises
land on the scan gently or over several segments, and a restart may start lower."""

from __future__ import annotations

import numpy as np
import pytest
from bench.corpus import load_corpus

from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import scan
from lookahead.planning.heuristic.planner import COARSE, COARSE_WIDE, HeuristicPlanner

#: largest share of junctions whose scan state may be a zero-acceleration fallback feed
#: (well below its cap); before the landings 33 % (coarse) and 36 % (wide) on the butterfly
MAX_FALLBACK_SHARE = 0.1


@pytest.mark.parametrize("layout", [COARSE, COARSE_WIDE], ids=["coarse", "wide"])
def test_butterfly_scan_rarely_falls_back_to_zero_acceleration_feeds(layout, monkeypatch):
    p = load_corpus("fast", pattern="n-butterfly")[0]
    cfg, m = p.config, p.config.machine
    path = p.path()
    request = PlanRequest(path, m.limits.scaled(cfg.planner.margin), PathState(0.0),
                          path.length, 0.0, p.geometry().feed_cap(), m.dt)
    shares: list[float] = []
    inner = scan.backward_scan

    def recording(solver, b, cap, w, *args, **kwargs):
        out, motions = inner(solver, b, cap, w, *args, **kwargs)
        fell = (out[:, 0] == w) & (out[:, 1] == 0.0) & (w < 0.9 * cap)
        shares.append(float(np.mean(fell)))
        return out, motions

    monkeypatch.setattr(scan, "backward_scan", recording)
    HeuristicPlanner(layouts=(layout,)).plan(request)
    assert shares, "the free-junction chain ran no backward scan"
    assert max(shares) <= MAX_FALLBACK_SHARE, shares
