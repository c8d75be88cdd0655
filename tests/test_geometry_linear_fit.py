"""`linear` fit: lines between the points, G2 corner blends within the tolerance (or exact
stops), streamed bit-identically whatever the chunking; planned paths stay on the polyline
(distances from `geometry.deviation`, limits from the finite-difference checker)."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from heuristic_paths import random_polyline
from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.geometry.deviation import path_deviation, polyline_distance
from lookahead.geometry.fits import fit_path
from lookahead.geometry.polyline import MAX_BLEND_TURN, LinearFit
from lookahead.planning.base import PathState, PlanRequest
from lookahead.sampling import sample_plan
from lookahead.stream.planners import make_planner

MACHINE = default_config().machine
SCALE = np.asarray(MACHINE.path_scale)
ZIGZAG = np.array([(0, 0), (200, 0), (200, 360), (400, 360), (400, 720), (600, 720), (0, 1440)],
                  dtype=float)


def plan(path, method: str = "heuristic"):
    """Plan the whole path as the engine does (limits times the margin), sample it."""
    limits = MACHINE.limits.scaled(default_config().planner.margin)
    result = make_planner(method).plan(PlanRequest(path, limits, PathState(0.0), path.length,
                                                   dt=MACHINE.dt))
    return result, sample_plan(path, result.profile, MACHINE.dt)


def test_zigzag_stays_within_tolerance_and_passes_the_checker() -> None:
    tol = 0.05
    path = fit_path(ZIGZAG, SCALE, "linear", tol)
    assert path.corners_s().size == 0  # every corner blended
    assert path.continuity() == 2
    geo = path_deviation(path, ZIGZAG, refine_above=0.5 * tol)
    assert geo.max <= tol + 1e-9
    assert geo.max >= tol - 1e-9  # the blends use the tolerance fully
    _, samples = plan(path)
    assert check_positions(samples.pos, MACHINE.limits, MACHINE.dt).ok
    dev = polyline_distance(samples.pos, ZIGZAG, SCALE)
    assert np.max(dev) <= tol + 1e-9
    assert np.mean(dev < 1e-9) > 0.9  # the straight parts are the programmed lines


def test_blends_are_faster_than_exact_stops_at_shallow_corners() -> None:
    # 20 deg turns every 50 mm (CAM-like): the blends keep the feed up, the stops do not;
    # with jmax 20000 mm/s^3 a 0.05 mm blend is crossed at ~20 mm/s (4 % faster than the
    # stops), a 0.5 mm one at ~90. (At the zig-zag's 90 deg corners a 0.05 mm blend is
    # crossed at ~5 mm/s: no faster than a stop; see bench/fidelity_bench.py.)
    pts = random_polyline([20.0] * 9, [True, False] * 5, [50.0] * 10, SCALE)
    times = [plan(fit_path(pts, SCALE, "linear", tol))[0].profile.duration
             for tol in (0.0, 0.05, 0.5)]
    assert times[2] < 0.8 * times[1] < 0.8 * 0.99 * times[0]  # more tolerance, more feed


def test_tolerance_zero_comes_to_rest_at_every_corner() -> None:
    path = fit_path(ZIGZAG, SCALE, "linear", 0.0)
    corners = path.corners_s()
    assert corners.size == len(ZIGZAG) - 2
    assert np.allclose(path.eval_s(corners, 0)[0], ZIGZAG[1:-1], atol=1e-9)
    result, samples = plan(path)
    assert check_positions(samples.pos, MACHINE.limits, MACHINE.dt).ok
    assert np.max(polyline_distance(samples.pos, ZIGZAG, SCALE)) <= 1e-9
    t = np.arange(0.0, result.profile.duration, 1e-4)
    s, v = result.profile.at(t)[:2]
    for sc in corners:
        near = np.abs(s - sc) < 1e-3
        assert near.any() and np.min(v[near]) < 1e-3, sc


def test_collinear_points_merge_and_reversals_stop() -> None:
    pts = np.array([(0, 0), (50, 0), (100, 0), (100, 100), (100, 40)], dtype=float)
    merged = fit_path(pts, SCALE, "linear", 0.1)
    plain = fit_path(pts[[0, 2, 3, 4]], SCALE, "linear", 0.1)
    assert merged.length == pytest.approx(plain.length, rel=1e-12)
    assert len(merged.breakpoints_s()) == len(plain.breakpoints_s())
    # the reversal at (100, 100) turns by 180 deg > MAX_BLEND_TURN: an exact stop there
    corner = merged.corners_s()
    assert corner.size == 1
    assert np.allclose(merged.eval_s(corner, 0)[0], [[100, 100]], atol=1e-9)
    assert math.pi > MAX_BLEND_TURN


def test_short_segments_share_their_length() -> None:
    pts = np.array([(0, 0), (1, 0), (1, 0.2), (2, 0.2), (2, 5)], dtype=float)
    scale = np.ones(2)
    fit = LinearFit(2, scale, tolerance=1.0)
    fit.extend(pts)
    path = fit.finish()
    u, back, on = (np.array(c) for c in zip(*fit.blends, strict=True))
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert np.all(back > 0) and np.all(on > 0)
    assert np.all(back <= 0.5 * seg[:-1] + 1e-15) and np.all(on <= 0.5 * seg[1:] + 1e-15)
    assert np.all(u[1:] - back[1:] >= u[:-1] + on[:-1] - 1e-12)  # no overlap
    assert np.any(back != on)  # a short line on one side only limits that side
    assert path_deviation(path, pts, refine_above=0.01).max <= 1.0 + 1e-9


def test_per_point_tolerance_and_errors() -> None:
    fit = LinearFit(2, SCALE, tolerance=0.05)
    fit.extend(ZIGZAG[:3])
    fit.extend(ZIGZAG[3:], tolerance=0.0)  # corners at points 3.. stop, 1 and 2 blend
    path = fit.finish()
    stops = [u for u, back, _ in fit.blends if back == 0.0]
    assert len(stops) == 3 and path.corners_s().size == 3
    with pytest.raises(ValueError, match="tolerance"):
        LinearFit(2, SCALE, tolerance=-1.0)
    with pytest.raises(ValueError, match="tolerance"):
        fit_path(ZIGZAG, SCALE, "linear", float("inf"))


polylines = st.integers(3, 12).flatmap(lambda n: st.tuples(
    st.lists(st.floats(1.0, 179.0), min_size=n - 1, max_size=n - 1),
    st.lists(st.booleans(), min_size=n - 1, max_size=n - 1),
    st.lists(st.floats(-2.0, 3.0).map(lambda e: 10.0**e), min_size=n, max_size=n),
    st.one_of(st.just(0.0), st.floats(0.0, 1.0)),
    st.sampled_from([1, 2])))


@settings(max_examples=60, deadline=None)
@given(polylines)
def test_random_polylines_stay_within_tolerance(case) -> None:
    angles, signs, lengths, tol, which = case
    scale = SCALE if which == 1 else np.ones(2)
    pts = random_polyline(angles, signs, lengths, scale)
    path = fit_path(pts, scale, "linear", tol)
    geo = path_deviation(path, pts, refine_above=0.5 * tol if tol > 0 else 0.0)
    assert geo.max <= tol + 1e-9
    ends = path.eval_u(np.array(path.u_range), 0)[0]
    assert np.allclose(ends, pts[[0, -1]], atol=1e-9)
    if tol == 0.0:  # every corner an exact stop, on its vertex
        corners = path.corners_s()
        assert corners.size == len(pts) - 2
        assert np.allclose(path.eval_s(corners, 0)[0], pts[1:-1], atol=1e-6)


@settings(max_examples=4, deadline=None)
@given(polylines)
def test_random_polylines_planned_stay_within_tolerance(case) -> None:
    angles, signs, lengths, tol, _ = case
    lengths = [min(x, 200.0) for x in lengths]  # a few seconds of motion each
    pts = random_polyline(angles, signs, lengths, SCALE)
    path = fit_path(pts, SCALE, "linear", tol)
    _, samples = plan(path)
    assert check_positions(samples.pos, MACHINE.limits, MACHINE.dt).ok
    assert np.max(polyline_distance(samples.pos, pts, SCALE)) <= tol + 1e-9


def stream_points(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(n, 2)) * rng.choice([0.05, 1.0, 30.0], size=(n, 1))
    steps[rng.random(n) < 0.3] = steps[0]  # collinear runs
    return np.cumsum(steps, axis=0)


@settings(max_examples=25, deadline=None)
@given(sizes=st.lists(st.integers(1, 40), min_size=1, max_size=20), probe=st.booleans(),
       method=st.sampled_from(["linear", "smooth"]))
def test_chunking_gives_the_same_geometry(sizes: list[int], probe: bool, method: str) -> None:
    from lookahead.geometry.fits import make_streaming_fit

    pts = stream_points(300, seed=len(sizes))
    tol = np.where(np.arange(300) % 7 == 0, 0.0, 0.2)
    one = make_streaming_fit(2, SCALE, method, 0.2)
    one.extend(pts, tol)
    chunked = make_streaming_fit(2, SCALE, method, 0.2)
    i = 0
    history = []
    for k in sizes:
        chunked.extend(pts[i : i + k], tol[i : i + k])
        i += k
        if probe and chunked.npoints >= 2:
            p = chunked.path()
            n = int(np.searchsorted(p.breakpoints_s(), chunked.final_length, side="right"))
            history.append((chunked.final_length, p.pp.c[:, : n - 1].copy()))
    chunked.extend(pts[i:], tol[i:])
    assert chunked.final_length == one.final_length > 0
    fa, fb = one.finish(), chunked.finish()
    assert np.array_equal(fa.pp.c, fb.pp.c) and np.array_equal(fa.pp.x, fb.pp.x)
    assert fa.length == fb.length
    lengths = [h[0] for h in history]
    assert lengths == sorted(lengths)
    for _, coef in history:  # the final geometry never changed
        assert np.array_equal(fa.pp.c[:, : coef.shape[1]], coef)


def test_streamed_job_through_the_engine_stays_on_the_polyline() -> None:
    from lookahead.protocol import Segment
    from lookahead.stream.engine import Engine

    rng = np.random.default_rng(3)
    n = 60
    pts = random_polyline(list(rng.uniform(5, 120, n - 2)), list(rng.random(n - 2) < 0.5),
                          list(rng.uniform(5, 80, n - 1)), SCALE)
    config = default_config()
    engine = Engine(config, make_planner("heuristic"))
    axes = tuple(config.machine.axes)
    bounds = [*range(0, n, 7), n]
    tolerances = [0.2, None, 0.0, 0.05]  # per segment; None: planner.tolerance (0.05)
    for seq, (a, b) in enumerate(itertools.pairwise(bounds)):
        engine.submit(Segment("cam", seq, axes, "points", b == n, points=pts[a:b],
                              fit="linear", tolerance=tolerances[seq % 4]))
    batches = []
    for _ in range(200_000):
        batch = engine.next_batch()
        if batch is not None:
            batches.append(batch)
            if batch.final:
                break
    assert batches and batches[-1].final and engine.fallbacks == 0
    pos = np.vstack([b.pos for b in batches])
    assert check_positions(pos, MACHINE.limits, MACHINE.dt).ok
    assert np.max(polyline_distance(pos, pts, SCALE)) <= 0.2 + 1e-9
    assert np.allclose(pos[-1], pts[-1], atol=1e-9)
    assert not [e for e in engine.drain_events() if e.type in ("rejected", "fault", "warning")]
