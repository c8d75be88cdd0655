"""Cutting and joining feed profiles (`planning.profile_ops`)."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PPoly

from lookahead.planning.base import FeedProfile
from lookahead.planning.profile_ops import concatenate, slice_profile


def _profile_with_a_sliver() -> FeedProfile:
    """s(t) of two cubics, the first 1e-17 s long (as the heuristic's profiles start), the
    second accelerating from 500 mm/s at 2500 mm/s^2 with jerk -25000 mm/s^3."""
    sliver = 1e-17
    c = np.array([[0.0, -25000.0 / 6.0], [0.0, 1250.0], [500.0, 500.0], [10.0, 10.0]])
    return FeedProfile(PPoly(c, np.array([0.0, sliver, 0.1]), extrapolate=False))


def test_a_slice_next_to_a_sliver_keeps_the_motion() -> None:
    """A slice whose start is within 1e-12 of a breakpoint takes the piece that holds the
    slice, not the sliver before it (it stretched the sliver's constant feed over the whole
    piece: a = 0 instead of 2500 mm/s^2)."""
    profile = _profile_with_a_sliver()
    t = np.linspace(0.0, 0.1, 11)
    want = profile.at(t + 1e-17)
    for cut in (slice_profile(profile, 0.0), concatenate(
            [slice_profile(profile, 0.0, 0.05), slice_profile(profile, 0.05)])):
        got = cut.at(np.clip(t, 0.0, cut.duration))
        np.testing.assert_allclose(got[:3], want[:3], rtol=1e-9, atol=1e-9)


def test_a_slice_inside_a_piece_is_its_taylor_shift() -> None:
    """Slicing at an interior time re-expands that piece about the cut: positions, feeds and
    accelerations equal the original's shifted in time."""
    profile = _profile_with_a_sliver()
    cut = slice_profile(profile, 0.03, 0.08)
    t = np.linspace(0.0, 0.05, 6)
    np.testing.assert_allclose(cut.at(t)[:3], profile.at(t + 0.03)[:3], rtol=1e-12)
    assert abs(cut.duration - 0.05) < 1e-15
