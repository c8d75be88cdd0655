"""Winding patterns: angle along the strokes, closure and coverage, presets, hoop layer."""

import math

import numpy as np
import pytest

from lookahead.geometry import (
    PRESETS,
    fit_points,
    helical_layer,
    hoop_layer,
    preset_points,
    winding_angle,
)

R = 100.0
SCALE = np.array([1.0, np.pi / 180 * R])


@pytest.mark.parametrize("name", PRESETS)
def test_preset_is_one_circuit_with_documented_assumptions(name: str) -> None:
    axes, pts, info = preset_points(name)
    assert axes == ["X", "C"] and pts.shape[1] == 2
    assert info.length == float(name.split("-")[1]) and info.radius == R
    assert info.circuits == 1 and info.strokes == 2
    assert info.circuits_in_layer == math.ceil(2 * math.pi * R * math.cos(math.radians(45)) / 10)
    assert math.gcd(info.pattern, info.circuits_in_layer) == 1
    closure = 2 * info.stroke_deg + 2 * info.dwell_deg
    assert closure == pytest.approx(360 * (info.wraps + info.pattern / info.circuits_in_layer))
    assert np.all(np.diff(pts[:, 1]) > 0)  # the mandrel keeps turning one way
    assert pts[:, 0].min() == pytest.approx(-info.overshoot, rel=1e-3)
    assert pts[:, 0].max() == pytest.approx(info.length + info.overshoot, rel=1e-3)
    step = np.hypot(np.diff(pts[:, 0]), R * np.radians(np.diff(pts[:, 1])))
    assert step.min() >= 1.0 and step.max() <= 5.0


def test_winding_angle_along_fitted_strokes_within_0_1_deg() -> None:
    _, pts, info = preset_points("tube-1450")
    path = fit_points(pts, SCALE, "cubic")
    u = np.linspace(*path.u_range, 200001)
    x = path.eval_u(u, 1)
    angle = np.degrees(np.arctan2(R * np.radians(x[1][:, 1]), x[1][:, 0]))
    on_tube = (x[0][:, 0] > 1.0) & (x[0][:, 0] < info.length - 1.0)
    forward = on_tube & (x[1][:, 0] > 0)
    backward = on_tube & (x[1][:, 0] < 0)
    assert forward.sum() > 1000 and backward.sum() > 1000
    assert np.max(np.abs(angle[forward] - 45.0)) < 0.1
    assert np.max(np.abs(angle[backward] - 135.0)) < 0.1
    steps = winding_angle(pts, R, folded=True)
    mid = (pts[:-1, 0] > 0) & (pts[:-1, 0] < info.length) & (pts[1:, 0] <= info.length) & (
        pts[1:, 0] >= 0)
    assert np.allclose(steps[mid], 45.0, atol=1e-9)


def test_layer_closes_and_bands_cover_the_circumference() -> None:
    pts, info = helical_layer(600.0, R, 30.0, 12.0, pattern=7, circuits=1)
    n = info.circuits_in_layer
    pts_all, _ = helical_layer(600.0, R, 30.0, 12.0, pattern=7, circuits=n)
    per_circuit = len(pts) - 1
    starts = pts_all[::per_circuit]
    assert len(starts) == n + 1
    assert np.allclose(starts[:, 0], 0.0)  # every circuit starts at the tube start
    phases = np.sort(np.mod(starts[:-1, 1], 360.0))
    assert np.allclose(np.diff(np.append(phases, phases[0] + 360)), 360.0 / n)
    assert np.mod(starts[-1, 1], 360.0) == pytest.approx(0.0, abs=1e-6) or np.mod(
        starts[-1, 1], 360.0) == pytest.approx(360.0, abs=1e-6)
    circumferential_band = info.band / math.cos(math.radians(info.alpha_deg))
    assert n * circumferential_band >= 2 * math.pi * R
    assert (n - 1) * circumferential_band < 2 * math.pi * R  # n is the least that covers
    assert info.dwell_deg >= 180.0


def test_turnaround_is_smooth() -> None:
    _, pts, _info = preset_points("tube-1450")
    path = fit_points(pts, SCALE, "cubic")
    s = np.linspace(0, path.length, 100001)
    d = path.eval_s(s)
    # curvature and its derivative stay bounded: no kinks at stroke/turnaround joins
    assert np.max(np.linalg.norm(d[2] * SCALE, axis=1)) < 2.0 / R
    assert np.max(np.linalg.norm(d[3] * SCALE, axis=1)) < 0.2 / R


def test_pattern_must_be_coprime() -> None:
    with pytest.raises(ValueError, match="gcd"):
        helical_layer(1000.0, R, 45.0, 10.0, pattern=3)  # n = 45


def test_presets_more_circuits_and_layer() -> None:
    _, one, _info = preset_points("tube-1450")
    _, three, info3 = preset_points("tube-1450", circuits=3)
    assert info3.strokes == 6 and len(three) == 3 * (len(one) - 1) + 1
    assert np.allclose(three[: len(one)], one)
    with pytest.raises(ValueError, match="preset"):
        preset_points("tube-1")
    with pytest.raises(ValueError, match="circuits"):
        preset_points("tube-1450", circuits=0)


def test_hoop_layer_advances_one_band_per_turn() -> None:
    pts = hoop_layer(200.0, R, 10.0)
    assert pts[0].tolist() == [0.0, 0.0] and pts[-1, 0] == pytest.approx(200.0)
    assert pts[-1, 1] == pytest.approx(360.0 * 20)
    assert np.allclose(np.diff(pts[:, 0]) / np.diff(pts[:, 1]), 10.0 / 360.0)
    angle = winding_angle(pts, R)
    assert np.allclose(angle, np.degrees(np.arctan2(2 * np.pi * R, 10.0)))
