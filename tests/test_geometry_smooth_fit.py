"""`smooth` fit: within the tolerance of the points' polyline, few pieces, G2, and a feed
set by the part's curvature, not by the number of its points (dense quantized CAM arcs)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lookahead.checker import check_positions
from lookahead.config import build_config
from lookahead.geometry.deviation import path_deviation, polyline_distance
from lookahead.geometry.fits import fit_path, make_streaming_fit
from lookahead.planning.base import PathState, PlanRequest
from lookahead.sampling import sample_plan
from lookahead.stream.planners import make_planner

#: a 2-axis mm machine whose acceleration limit lets the circle's curvature, not an axis's
#: velocity, set the feed (~sqrt(0.6 amax R) = 300 mm/s < vmax)
MACHINE = build_config({"machine": {
    "axes": ["X", "Y"], "units": ["mm", "mm"], "vmax": [500.0, 500.0],
    "amax": [100.0, 100.0], "jmax": [2000.0, 2000.0], "path_scale": [1.0, 1.0]}}).machine
SCALE = np.ones(2)
#: 10k 1 mm moves make one turn
R = 10_000 / (2 * np.pi)


def circle(step: float, n: int, quantum: float = 1e-3) -> np.ndarray:
    """n moves of `step` mm along a circle of radius R, coordinates rounded to `quantum`."""
    th = np.arange(n + 1) * step / R
    return np.round(np.column_stack([R * np.cos(th), R * np.sin(th)]) / quantum) * quantum


def random_polyline(angles_deg: list[float], signs: list[bool], lengths: list[float]
                    ) -> np.ndarray:
    """Points whose polyline turns by the given angles (deg, left or right)."""
    heading = np.cumsum([0.0] + [np.radians(a) * (1 if s else -1)
                                 for a, s in zip(angles_deg, signs, strict=True)])
    steps = np.asarray(lengths)[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])


def plan(path, method: str = "heuristic"):
    limits = MACHINE.limits.scaled(0.98)
    result = make_planner(method).plan(PlanRequest(path, limits, PathState(0.0), path.length,
                                                   dt=MACHINE.dt))
    return result, sample_plan(path, result.profile, MACHINE.dt)


def test_dense_circle_is_followed_at_the_feed_of_its_curvature() -> None:
    tol = 0.05
    pts = circle(1.0, 10_000)  # 10k 1 mm moves, one turn
    path = fit_path(pts, SCALE, "smooth", tol)
    assert len(path.breakpoints_s()) < 0.6 * len(pts)  # fewer pieces than points
    geo = path_deviation(path, pts, per_interval=8, refine_above=0.5 * tol)
    assert geo.max <= tol + 1e-9
    # curvature: the circle's, without the quantization noise (away from the ends,
    # where the path starts and stops on a tangent line)
    s = np.linspace(0.02, 0.98, 200_001) * path.length
    kappa = np.linalg.norm(path.eval_s(s, 2)[2], axis=1) * R
    assert np.min(kappa) > 0.85 and np.max(kappa) < 1.15
    result, samples = plan(path)
    assert check_positions(samples.pos, MACHINE.limits, MACHINE.dt).ok
    assert np.max(polyline_distance(samples.pos, pts, SCALE)) <= tol + 1e-9
    # the reference: the same circle without noise, fitted by the C2 cubic (exact to ~1e-9)
    exact = fit_path(circle(1.0, 10_000, quantum=1e-12), SCALE, "cubic")
    ideal = plan(exact)[0].profile.duration
    assert result.profile.duration < 1.15 * ideal
    # the point count does not set the feed: twice the points, the same circle
    dense = fit_path(circle(0.5, 20_000), SCALE, "smooth", tol)
    assert plan(dense)[0].profile.duration < 1.15 * ideal
    # the service's default planner too (C4 quintic: no jumps of d3x/ds3 at the knots)
    lp, lp_samples = plan(path, "lp")
    assert check_positions(lp_samples.pos, MACHINE.limits, MACHINE.dt).ok
    assert lp.profile.duration < 1.15 * plan(exact, "lp")[0].profile.duration


@pytest.mark.slow
def test_dense_circle_linear_follows_the_noise() -> None:
    # the linear fit follows every quantized point: its corners cost far more time (8x)
    pts = circle(1.0, 10_000)
    smooth = plan(fit_path(pts, SCALE, "smooth", 0.05))[0].profile.duration
    assert plan(fit_path(pts, SCALE, "linear", 0.05))[0].profile.duration > 2.0 * smooth


polylines = st.integers(3, 14).flatmap(lambda n: st.tuples(
    st.lists(st.floats(1.0, 179.0), min_size=n - 1, max_size=n - 1),
    st.lists(st.booleans(), min_size=n - 1, max_size=n - 1),
    st.lists(st.floats(-2.0, 3.0).map(lambda e: 10.0**e), min_size=n, max_size=n),
    st.one_of(st.just(0.0), st.floats(0.0, 1.0))))


@settings(max_examples=30, deadline=None)
@given(polylines)
def test_random_polylines_stay_within_tolerance(case) -> None:
    angles, signs, lengths, tol = case
    pts = random_polyline(angles, signs, lengths)
    path = fit_path(pts, SCALE, "smooth", tol)
    assert path.continuity() == 2
    geo = path_deviation(path, pts, refine_above=0.5 * tol if tol > 0 else 0.0)
    assert geo.max <= tol + 1e-9
    ends = path.eval_u(np.array(path.u_range), 0)[0]
    assert np.allclose(ends, pts[[0, -1]], atol=1e-9)
    if tol == 0.0:  # exact stops at every corner
        assert path.corners_s().size == len(pts) - 2


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000), tol=st.sampled_from([0.01, 0.05, 0.3]),
       wiggle=st.sampled_from([0.0, 0.01, 0.2]))
def test_noisy_arcs_and_lines_stay_within_tolerance(seed: int, tol: float, wiggle: float
                                                    ) -> None:
    rng = np.random.default_rng(seed)
    # CAM-like: arcs of random radius in short moves, a long line, noise on every point
    th = np.cumsum(rng.uniform(0.002, 0.05, 300)) * rng.choice([-1, 1])
    radius = rng.uniform(5, 500)
    arc = radius * np.column_stack([np.cos(th), np.sin(th)])
    line = arc[-1] + np.outer(np.linspace(0, 1, 40)[1:], rng.normal(size=2) * 300)
    pts = np.vstack([arc, line]) + wiggle * rng.normal(size=(len(arc) + len(line), 2))
    path = fit_path(pts, SCALE, "smooth", tol)
    assert path_deviation(path, pts, refine_above=0.5 * tol).max <= tol + 1e-9


def test_lock_move_does_not_swing_past_the_end() -> None:
    # the carriage comes to X = 0 in 1.4 mm steps, then the mandrel turns 558 deg with X
    # held (one move): the cubic swings X far past 0, smooth and linear do not
    scale = np.array([1.0, np.pi / 180 * 100])
    x = np.arange(100, -0.7, -1.4)
    c = np.linspace(0, 30, x.size)
    pts = np.vstack([np.column_stack([x, c]), [[x[-1], c[-1] + 558.0]]])
    lowest = {}
    for fit in ("cubic", "smooth", "linear"):
        path = fit_path(pts, scale, fit, 0.05)
        lowest[fit] = float(np.min(path.eval_s(np.linspace(0, path.length, 20001), 0)[0][:, 0]))
    assert lowest["cubic"] < x[-1] - 10.0
    assert lowest["smooth"] >= x[-1] - 0.05 - 1e-9
    assert lowest["linear"] >= x[-1] - 0.05 - 1e-9


def test_errors() -> None:
    with pytest.raises(ValueError, match="tolerance"):
        make_streaming_fit(2, SCALE, "smooth", -1.0)
    fit = make_streaming_fit(2, SCALE, "smooth", 0.05)
    fit.extend([[0.0, 0.0]])
    with pytest.raises(ValueError, match="at least 2"):
        fit.path()
