"""The TOPP-RA v+a time bound (`planning.bounds.toppra_time_bound`) with feed caps: the
corpus's G-code jobs run at their F words, so the bound must charge the caps too."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.config import default_config
from lookahead.geometry import fit_points
from lookahead.planning.base import FeedCap
from lookahead.planning.bounds import toppra_time_bound

pytest.importorskip("toppra")


def test_a_feed_cap_is_charged_and_the_bound_stays_below_the_capped_time() -> None:
    m = default_config().machine
    pts = np.column_stack([np.linspace(0.0, 400.0, 81), np.linspace(0.0, 90.0, 81)])
    path = fit_points(pts, np.asarray(m.path_scale))
    free = toppra_time_bound(path, m.limits, gridpoints=400)
    # half the path at 20 mm/s, the other half uncapped
    half = path.length / 2.0
    cap = FeedCap(np.array([0.0, half, path.length]), np.array([20.0, 1e9]))
    capped = toppra_time_bound(path, m.limits, gridpoints=400, feed_cap=cap)
    assert capped > free
    # at least the capped half at its cap, at most that plus the free bound
    assert half / 20.0 * (1 - 1e-3) <= capped <= half / 20.0 + free
