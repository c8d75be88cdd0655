"""The independent distance-from-polyline measure, and how far the interpolating fits leave
the polyline (`excursions`; `warning` events from the engine; `lookahead plan` output)."""

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lookahead.config import default_config
from lookahead.geometry.deviation import (
    PolylineDistance,
    excursions,
    path_deviation,
    polyline_distance,
)
from lookahead.geometry.fits import fit_path
from lookahead.protocol import Event, Segment

SCALE = np.asarray(default_config().machine.path_scale)
ZIGZAG = np.array([(0, 0), (200, 0), (200, 360), (400, 360), (400, 720), (600, 720), (0, 1440)],
                  dtype=float)


def brute_force(x: np.ndarray, pts: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Distance of every x to every segment, the minimum (O(n m), for checking)."""
    xs, ps = x * scale, pts * scale
    a, b = ps[:-1], ps[1:]
    ab = b - a
    t = np.clip(np.einsum("mkd,kd->mk", xs[:, None, :] - a[None], ab)
                / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
    foot = a[None] + t[..., None] * ab[None]
    return np.min(np.linalg.norm(xs[:, None, :] - foot, axis=-1), axis=1)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 60), spread=st.sampled_from([0.01, 1, 300]))
def test_distance_matches_brute_force(seed: int, n: int, spread: float) -> None:
    rng = np.random.default_rng(seed)
    # mixed spacings: many short moves and a few very long ones
    steps = rng.normal(size=(n - 1, 2)) * rng.choice([0.01, 1.0, 1000.0], size=(n - 1, 1))
    pts = np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])
    x = pts[rng.integers(0, n, 200)] + spread * rng.normal(size=(200, 2))
    got = polyline_distance(x, pts, SCALE)
    assert np.allclose(got, brute_force(x, pts, SCALE), rtol=1e-12, atol=1e-9)


def test_points_on_the_polyline_are_at_distance_zero() -> None:
    measure = PolylineDistance(ZIGZAG, SCALE)
    f = np.linspace(0, 1, 101)[:, None]
    on = np.vstack([a + f * (b - a) for a, b in itertools.pairwise(ZIGZAG)])
    assert np.max(measure(on)) < 1e-9
    assert measure(np.array([[200.0 + 3.0, 100.0]]))[0] == np.float64(3.0)


def test_refined_maximum_is_the_true_one() -> None:
    # a circle's arc against its chords: the largest distance is the sagitta, at the
    # middle of each arc; the sampling alone would miss it by up to ~1e-4 relative
    r, n = 50.0, 7
    th = np.linspace(0, np.pi, n)
    pts = np.column_stack([r * np.cos(th), r * np.sin(th)])
    fine = np.linspace(0, np.pi, 4001)
    arc = fit_path(np.column_stack([r * np.cos(fine), r * np.sin(fine)]), np.ones(2), "linear",
                   0.0)
    d = path_deviation(arc, pts, per_interval=1, refine_above=0.0)
    sagitta = r * (1 - np.cos(np.pi / (n - 1) / 2))
    # the arc itself is a 4001-point polyline: its own chords shave at most r (1 - cos(h/2))
    shave = r * (1 - np.cos(np.pi / 4000 / 2))
    assert sagitta - shave - 1e-9 <= d.max <= sagitta + 1e-9


def test_cubic_excursions_are_found_and_linear_has_none() -> None:
    cubic = fit_path(ZIGZAG, SCALE, "cubic")
    found = excursions(cubic, ZIGZAG, 0.05)
    assert found and max(e.dev for e in found) > 10.0
    for e in found:
        assert 0 <= e.s_start <= e.s_max <= e.s_end <= cubic.length
    worst = max(found, key=lambda e: e.dev)
    x = cubic.eval_s(np.array([worst.s_max]), 0)[0]
    assert polyline_distance(x, ZIGZAG, SCALE)[0] == np.float64(worst.dev)
    assert excursions(fit_path(ZIGZAG, SCALE, "linear", 0.05), ZIGZAG, 0.05 + 1e-9) == []


def test_engine_warns_when_a_cubic_job_leaves_the_polyline() -> None:
    from lookahead.stream.engine import Engine
    from lookahead.stream.planners import make_planner

    config = default_config()
    engine = Engine(config, make_planner("heuristic"))
    axes = tuple(config.machine.axes)
    for fit, expect in (("cubic", True), ("linear", False)):
        job = f"zz-{fit}"
        for seq, (a, b) in enumerate([(0, 3), (3, 7)]):
            engine.submit(Segment(job, seq, axes, "points", seq == 1,
                                  points=ZIGZAG[a:b], fit=fit))
        warnings = [e for e in engine.drain_events() if e.type == "warning"]
        assert bool(warnings) == expect, fit
        for w in warnings:
            assert w.job == job and w.extra["deviation"] > w.extra["tolerance"] == 0.05
            assert "polyline" in w.extra["reason"]
            again = Event.decode(w.encode())
            assert again.type == "warning" and again.extra["seq"] == w.extra["seq"]


PROGRAM = """%
G21 G90 G64 P0.2 (blend within 0.2 mm)
G1 X200 A0 F30000
G1 X200 A360
G61 (exact stops from here)
G1 X400 A360
G1 X400 A720
G64 (the configured default)
G1 X600 A720
G61.1
G1 X0 A1440
M2
"""


def test_gcode_path_control_and_plan_output(tmp_path, capsys) -> None:
    import argparse

    from lookahead import plan_cli
    from lookahead.geometry.gcode import read_gcode

    result = read_gcode(PROGRAM)
    assert np.allclose(result.tolerance[:2], 0.2)
    assert np.all(result.tolerance[2:4] == 0.0)
    assert np.isnan(result.tolerance[4]) and result.tolerance[5] == 0.0
    inch = read_gcode("G20 G64 P0.01\nG1 X1 A0\n")
    assert inch.tolerance[0] == np.float64(0.01 * 25.4)
    for bad in ("G1 X1 P0.1\n", "G64 P-1\nG1 X1\n"):
        try:
            read_gcode(bad)
        except ValueError as exc:
            assert "P" in str(exc)
        else:
            raise AssertionError(bad)
    path = fit_path(np.vstack([[0.0, 0.0], result.points]), SCALE, "linear",
                    np.concatenate([[np.nan], result.tolerance]))
    # a corner takes the mode of the move that ends there: exact stops at the ends of
    # the two G61 moves (X400 A360, X400 A720); G64 blends X600 A720 with the default;
    # G61.1 governs only the last move, which ends the path
    assert path.corners_s().size == 2
    nc = tmp_path / "zigzag.nc"
    nc.write_text(PROGRAM)
    parser = argparse.ArgumentParser()
    plan_cli.add_parser(parser.add_subparsers())
    rc = plan_cli.run(parser.parse_args(["plan", str(nc), "--method", "heuristic"]))
    out = capsys.readouterr().out
    assert rc == 0
    line = next(x for x in out.splitlines() if x.startswith("deviation"))
    assert "fit smooth" in line and float(line.split()[1]) <= 0.2 + 1e-9
    rc = plan_cli.run(parser.parse_args(["plan", str(nc), "--method", "heuristic", "--fit",
                                         "cubic"]))
    out = capsys.readouterr().out
    assert rc == 0 and "excursions" in out


def test_polyline_distance_in_batches_equals_all_at_once(monkeypatch):
    """Positions are measured in batches of `_BATCH` (memory: 3M samples at once peaked at
    8.9 GB); each position is measured alone, so batching changes no value."""
    from lookahead.geometry import deviation

    rng = np.random.default_rng(7)
    pts = np.cumsum(rng.normal(size=(300, 3)), axis=0)
    scale = np.array([1.0, 2.0, 0.5])
    pos = pts[rng.integers(0, 300, 5000)] + rng.normal(scale=0.7, size=(5000, 3))
    measure = deviation.PolylineDistance(pts, scale)
    whole = measure(pos)
    monkeypatch.setattr(deviation, "_BATCH", 333)
    assert np.array_equal(measure(pos), whole)
    brute = np.min(measure._to_pieces(pos * scale, np.broadcast_to(
        np.arange(measure._a.shape[0]), (len(pos), measure._a.shape[0]))), axis=1)
    np.testing.assert_allclose(whole, brute, rtol=0, atol=1e-12)
