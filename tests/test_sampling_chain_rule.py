"""The sampler puts samples exactly on the path with chain-rule derivatives, holds the
end state, and never creeps backwards at zero feed."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PPoly

from lookahead.geometry.spline_path import fit_points
from lookahead.planning.base import FeedProfile
from lookahead.sampling import sample_plan, sample_profile, sample_times

SCALE = np.array([1.0, np.pi / 180.0 * 100.0])


def curved_path():
    th = np.linspace(0.0, np.pi, 40)
    return fit_points(np.c_[50.0 * np.cos(th), 30.0 * np.sin(th) * 180.0 / np.pi], SCALE)


def cubic_profile(length: float, duration: float) -> FeedProfile:
    """Rest-to-rest s(t) = L (3 tau^2 - 2 tau^3), tau = t / T."""
    T = duration
    c = np.array([[-2.0 * length / T**3], [3.0 * length / T**2], [0.0], [0.0]])
    return FeedProfile(PPoly(c, np.array([0.0, T])))


def test_samples_match_numerical_derivatives_of_positions():
    path = curved_path()
    profile = cubic_profile(path.length, 2.0)
    h = 1e-5
    t = np.linspace(0.1, 1.9, 7)
    mid = sample_profile(path, profile, t)
    plus = sample_profile(path, profile, t + h).pos
    minus = sample_profile(path, profile, t - h).pos
    np.testing.assert_allclose(mid.vel, (plus - minus) / (2 * h), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(mid.acc, (plus - 2 * mid.pos + minus) / h**2, rtol=1e-3,
                               atol=1e-2)
    # positions are on the path at s(t)
    s = profile.at(t)[0]
    np.testing.assert_allclose(mid.pos, path.eval_s(s, order=0)[0], atol=1e-12)


def test_sample_plan_covers_duration_and_holds_end():
    path = curved_path()
    profile = cubic_profile(path.length, 1.2345)
    dt = 0.01
    samples = sample_plan(path, profile, dt)
    assert len(samples) == len(sample_times(1.2345, dt)) == 125
    np.testing.assert_allclose(samples.pos[-1], path.eval_s(np.array([path.length]), 0)[0][0],
                               atol=1e-9)
    np.testing.assert_allclose(samples.vel[-1], 0.0, atol=1e-9)


def test_no_backward_creep_near_zero_feed():
    # a profile whose s(t) wobbles by 1e-13 backwards around a stop
    c = np.array([[0.0, 0.0], [0.0, 0.0], [1e-13, -1e-13], [10.0, 10.0 + 1e-13]])
    profile = FeedProfile(PPoly(c, np.array([0.0, 1.0, 2.0])))
    path = curved_path()
    samples = sample_profile(path, profile, np.linspace(0.0, 2.0, 50))
    s = path.s_of_u(path.u_of_s(profile.at(np.linspace(0.0, 2.0, 50))[0]))
    assert np.all(np.diff(np.maximum.accumulate(s)) >= 0)
    assert np.all(np.isfinite(samples.pos))
    np.testing.assert_array_equal(np.diff(samples.pos[25:], axis=0), 0.0)
