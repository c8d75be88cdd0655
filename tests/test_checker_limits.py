"""The finite-difference checker catches planted violations of each kind on each axis,
also across batch boundaries, and accepts motions that are within the limits."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import LimitChecker, check_positions
from lookahead.config import default_config

MACHINE = default_config().machine
DT = MACHINE.dt
LIMITS = MACHINE.limits  # the winder's defaults


def smooth_motion(n: int = 400) -> np.ndarray:
    """Positions of a gentle sine motion, well inside all limits, offset far from 0."""
    t = np.arange(n) * DT
    return np.c_[1000.0 + 5.0 * np.sin(2 * np.pi * t), 50000.0 + 3.0 * np.cos(2 * np.pi * t)]


def test_smooth_motion_passes_and_reports_peaks():
    rep = check_positions(smooth_motion(), LIMITS, DT)
    assert rep.ok and rep.violations == 0 and rep.first is None
    # velocity amplitude 2 pi 5 = 31.4 mm/s on X
    assert rep.peak_fraction["v"][0] == pytest.approx(2 * np.pi * 5 / 500.0, rel=1e-3)


def plant(kind: str, axis: int, k: int, pos: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Add a single isolated step of order 1/2/3 at sample k that exceeds `kind`'s limit
    by 10 % while staying below the lower orders' limits where possible."""
    p = pos.copy()
    lim = limit[axis]
    if kind == "v":
        p[k:, axis] += 1.1 * lim * DT  # one velocity sample 1.1 vmax (a and j also jump)
    elif kind == "a":
        p[k:, axis] += 1.1 * lim * DT**2 * np.arange(1, len(p) - k + 1)
    else:
        steps = np.arange(1, len(p) - k + 1)
        p[k:, axis] += 1.1 * lim * DT**3 * steps * (steps + 1) * (steps + 2) / 6.0
    return p


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("kind", ["v", "a", "j"])
def test_planted_violation_is_caught(kind, axis):
    limit = {"v": LIMITS.vmax, "a": LIMITS.amax, "j": LIMITS.jmax}[kind]
    pos = plant(kind, axis, 200, smooth_motion(), limit)
    if kind == "a":
        pos = pos[:205]  # before the velocity it builds up exceeds vmax
    rep = check_positions(pos, LIMITS, DT)
    assert rep.counts[kind][axis] >= 1
    assert rep.counts[kind][1 - axis] == 0
    assert rep.first is not None and rep.first.axis == axis
    assert rep.peak_fraction[kind][axis] > 1.0


@pytest.mark.parametrize("kind", ["v", "a", "j"])
@pytest.mark.parametrize("split_offset", [-2, -1, 0, 1, 2])
def test_violation_straddling_batch_boundary(kind, split_offset):
    limit = {"v": LIMITS.vmax, "a": LIMITS.amax, "j": LIMITS.jmax}[kind]
    pos = plant(kind, 1, 200, smooth_motion(), limit)[:206]
    whole = check_positions(pos, LIMITS, DT)
    checker = LimitChecker(LIMITS, DT)
    cut = 200 + split_offset
    for chunk in (pos[:cut], pos[cut:cut + 1], pos[cut + 1:]):
        checker.feed(chunk)
    rep = checker.report()
    assert rep.counts == whole.counts
    assert rep.first == whole.first
    assert rep.samples == len(pos)
    assert rep.counts[kind][1] >= 1


def test_batches_of_one_equal_one_batch():
    pos = plant("j", 0, 150, smooth_motion(300), LIMITS.jmax)
    checker = LimitChecker(LIMITS, DT)
    for row in pos:
        checker.feed(row[None, :])
    assert checker.report().to_dict() == check_positions(pos, LIMITS, DT).to_dict()


def test_exactly_at_limit_passes_despite_large_offsets():
    # constant jerk exactly at jmax from a large position offset: rounding only
    t = np.arange(50) * DT
    x = 1e5 + LIMITS.jmax[0] * t**3 / 6.0
    pos = np.c_[x, np.full_like(x, 2e5)]
    rep = check_positions(pos, LIMITS, DT)
    assert rep.counts["j"] == [0, 0]
    assert rep.peak_fraction["j"][0] == pytest.approx(1.0, rel=1e-3)
