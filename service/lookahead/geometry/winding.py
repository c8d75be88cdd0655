"""Filament-winding patterns on a cylindrical mandrel, as point streams in machine axes
X (mm, carriage, along the mandrel axis) and C (deg, mandrel rotation, unwrapped).

Assumptions (also recorded in `PresetInfo`):
- Cylinder of radius R (mm); the fibre touches it at the carriage position, so a fibre
  at winding angle alpha (measured from the mandrel axis) obeys dX = R cot(alpha) dC
  (C in rad), and its length element is sqrt(dX^2 + (R dC)^2).
- Helical layer: the constant-angle strokes cover the whole tube length L (X from 0 to
  L and back); the turnarounds happen beyond the tube ends (on the domes / pin rings).
- Circuits per layer n = ceil(2 pi R cos(alpha) / B) for band width B (mm); pattern
  (skip) p with gcd(p, n) = 1; closure 2 theta_stroke + 2 theta_dwell = 360 (m + p/n) deg,
  with the smallest integer m that gives theta_dwell >= `min_dwell_deg` (default 180).
  Circuit j then starts at 360 p j / n (mod 360): the n circuits lay bands at all n
  positions around the circumference, and n B / cos(alpha) >= 2 pi R, so they cover it.
- Turnaround: C keeps turning at the stroke rate while dX/dC reverses from +R cot(alpha)
  to -R cot(alpha) along a septic smoothstep S (S', S'', S''' = 0 at both ends), so X(C)
  is C3 at the joins and the turnaround is smooth enough for a jerk-limited machine.
  X overshoots the tube end by e = R cot(alpha) theta_dwell * 0.36328125 (theta in rad).
- Hoop layer: alpha ~ 90 deg, X advances one band width B per mandrel revolution.
- Points are spaced ~`spacing` mm of fibre (default 2 mm): exactly on strokes; uniform in
  C within a turnaround, where the fibre spacing varies by up to a factor sqrt(1 + cot^2
  alpha) around it (1.58 .. 2.24 mm for the presets).
- Presets `tube-1450` / `tube-9570` (the paper's Examples 1 and 2, tube lengths 1450 and
  9570 mm): R = 100 mm (path_scale for C = pi/180 * 100), alpha = 45 deg, B = 10 mm,
  p = 1, one circuit (two strokes and two turnarounds) unless `circuits=` says otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

AXES = ("X", "C")
PRESETS = ("tube-1450", "tube-9570")
_PRESET_LENGTHS = {"tube-1450": 1450.0, "tube-9570": 9570.0}
_PRESET_R, _PRESET_ALPHA, _PRESET_B, _PRESET_P = 100.0, 45.0, 10.0, 1
#: integral of S over [0, 1/2] doubled, subtracted from 1/2: the turnaround overshoot factor
OVERSHOOT = 0.36328125


@dataclass(frozen=True)
class PresetInfo:
    """Assumptions behind a generated helical pattern (lengths mm, angles deg)."""

    name: str
    description: str
    length: float
    radius: float
    alpha_deg: float
    band: float
    circuits_in_layer: int
    pattern: int
    wraps: int
    stroke_deg: float
    dwell_deg: float
    overshoot: float
    spacing: float
    circuits: int
    strokes: int


def circuits_per_layer(radius: float, alpha_deg: float, band: float) -> int:
    """n = ceil(2 pi R cos(alpha) / B)."""
    return math.ceil(2.0 * math.pi * radius * math.cos(math.radians(alpha_deg)) / band - 1e-12)


def _smoothstep7(tau: np.ndarray) -> np.ndarray:
    return tau**4 * (35.0 - 84.0 * tau + 70.0 * tau**2 - 20.0 * tau**3)


def _turn_profile(tau: np.ndarray) -> np.ndarray:
    """G(tau) = integral of (1 - 2 S) from 0: X offset per (R cot(alpha) theta_dwell)."""
    return tau - 2.0 * tau**5 * (7.0 - 14.0 * tau + 10.0 * tau**2 - 2.5 * tau**3)


def _steps(fibre_length: float, spacing: float) -> int:
    return max(1, math.ceil(fibre_length / spacing))


def _turn_fibre_length(k: float, radius: float, dwell: float) -> float:
    """Fibre length of a turnaround (dwell in rad), by the trapezoid rule on 2001 nodes."""
    tau = np.linspace(0.0, 1.0, 2001)
    speed = np.sqrt((k * (1.0 - 2.0 * _smoothstep7(tau))) ** 2 + radius**2) * dwell
    return float(np.trapezoid(speed, tau))


def helical_layer(
    length: float,
    radius: float,
    alpha_deg: float,
    band: float,
    pattern: int = 1,
    circuits: int = 1,
    spacing: float = 2.0,
    min_dwell_deg: float = 180.0,
    name: str = "helical",
) -> tuple[np.ndarray, PresetInfo]:
    """Points (n, 2) [X mm, C deg] of `circuits` helical circuits starting at X = 0, C = 0,
    and the pattern's `PresetInfo`. Each circuit: stroke 0 -> L, turnaround, stroke L -> 0,
    turnaround."""
    if not (0.0 < alpha_deg < 90.0) or min(length, radius, band, spacing) <= 0:
        raise ValueError("helical_layer: need 0 < alpha < 90 deg and positive sizes")
    n = circuits_per_layer(radius, alpha_deg, band)
    if math.gcd(pattern, n) != 1:
        raise ValueError(f"pattern: gcd({pattern}, {n} circuits) must be 1")
    k = radius / math.tan(math.radians(alpha_deg))  # mm of X per rad of C
    stroke = length / k  # rad
    wraps = math.ceil((math.radians(min_dwell_deg) + stroke) / math.pi - pattern / n)
    dwell = math.pi * (wraps + pattern / n) - stroke
    overshoot = k * dwell * OVERSHOOT

    n_stroke = _steps(length / math.cos(math.radians(alpha_deg)), spacing)
    n_turn = _steps(_turn_fibre_length(k, radius, dwell), spacing)
    tau_s = np.arange(n_stroke) / n_stroke
    tau_t = np.arange(n_turn) / n_turn
    circuit_x = np.concatenate([
        length * tau_s,
        length + k * dwell * _turn_profile(tau_t),
        length * (1.0 - tau_s),
        -k * dwell * _turn_profile(tau_t),
    ])
    circuit_c = np.concatenate([
        stroke * tau_s,
        stroke + dwell * tau_t,
        stroke + dwell + stroke * tau_s,
        2.0 * stroke + dwell + dwell * tau_t,
    ])
    advance = 2.0 * (stroke + dwell)
    x = np.concatenate([circuit_x] * circuits + [[0.0]])
    c = np.concatenate([circuit_c + j * advance for j in range(circuits)] + [[circuits * advance]])
    info = PresetInfo(
        name=name,
        description=(
            f"helical layer on a {length:g} mm tube, R {radius:g} mm, alpha {alpha_deg:g} deg, "
            f"band {band:g} mm: {circuits} of {n} circuits, pattern {pattern}"
        ),
        length=length, radius=radius, alpha_deg=alpha_deg, band=band,
        circuits_in_layer=n, pattern=pattern, wraps=wraps,
        stroke_deg=math.degrees(stroke), dwell_deg=math.degrees(dwell),
        overshoot=overshoot, spacing=spacing, circuits=circuits, strokes=2 * circuits,
    )
    return np.column_stack([x, np.degrees(c)]), info


def hoop_layer(length: float, radius: float, band: float, spacing: float = 2.0) -> np.ndarray:
    """Points (n, 2) [X mm, C deg] of a hoop layer: X from 0 to L, advancing B per turn."""
    if min(length, radius, band, spacing) <= 0:
        raise ValueError("hoop_layer: sizes must be positive")
    turns = length / band
    per_rad = math.hypot(radius, band / (2.0 * math.pi))
    steps = _steps(2.0 * math.pi * turns * per_rad, spacing)
    tau = np.linspace(0.0, 1.0, steps + 1)
    return np.column_stack([length * tau, 360.0 * turns * tau])


def winding_angle(points: np.ndarray, radius: float, folded: bool = False) -> np.ndarray:
    """Winding angle (deg) per step between consecutive [X mm, C deg] points:
    atan2(R dC_rad, dX), i.e. alpha on a stroke towards +X and 180 - alpha back.
    `folded=True` maps to [0, 90]: the angle between fibre and mandrel axis."""
    pts = np.asarray(points, dtype=float)
    d = np.diff(pts, axis=0)
    angle = np.degrees(np.arctan2(radius * np.radians(d[:, 1]), d[:, 0]))
    if folded:
        angle = np.degrees(np.arctan2(np.abs(radius * np.radians(d[:, 1])), np.abs(d[:, 0])))
    return angle


def preset_points(
    name: str, circuits: int | str | None = None
) -> tuple[list[str], np.ndarray, PresetInfo]:
    """(axes, points (n, 2) [X mm, C deg], PresetInfo) of a named preset.

    circuits: None -> 1 circuit (two strokes); an int; or "layer" for the whole layer."""
    if name not in _PRESET_LENGTHS:
        raise ValueError(f"preset: unknown name {name!r}, expected one of {PRESETS}")
    n_layer = circuits_per_layer(_PRESET_R, _PRESET_ALPHA, _PRESET_B)
    if circuits is None:
        count = 1
    elif circuits == "layer":
        count = n_layer
    elif isinstance(circuits, int) and not isinstance(circuits, bool) and circuits >= 1:
        count = circuits
    else:
        raise ValueError(f"circuits: expected a positive int or 'layer', got {circuits!r}")
    points, info = helical_layer(
        _PRESET_LENGTHS[name], _PRESET_R, _PRESET_ALPHA, _PRESET_B, _PRESET_P,
        circuits=count, name=name,
    )
    return list(AXES), points, info
