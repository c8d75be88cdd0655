"""Real CAM output: winding G-code from fiberpath (the open winder CAM on PyPI, in the
`bench` extra only), read with `lookahead.geometry.gcode` and sent as `points` segments.

fiberpath writes X (carriage, mm), A (mandrel, deg) and B (delivery head, deg) on G0
moves, 1 mm carriage steps, G92 resets of A between layers and circuits (read as offsets:
the machine axis stays unwrapped), repeated and zero-length moves, and locks where the
mandrel turns (lockDegrees) with X held. The B axis (delivery head) is a separate issue:
here X -> X and A -> C of the two-drive winder, and B is DROPPED (every name says
`-noB`); moves that only turned B become zero-length moves, which the service skips.
G0 carries no feed cap in our reader (fiberpath's F is ignored); the winder plans to its
limits. C's path_scale uses the mandrel's diameter (R = D/2; for cones and the von Karman
profile the base diameter).

Beside them (and in their place if fiberpath is not installed) `fiberpath_style`, a small
generator of programs of the same shape (1 mm moves, G92 resets, zero-length moves, a
~558 deg lock with X held), named `cam-style-*`.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from bench.corpus.base import CorpusPath, point_segments, winder_config
from lookahead.geometry.gcode import read_gcode

#: points per segment, as `lookahead publish` sends G-code by default
CHUNK = 500


def fiberpath_available() -> bool:
    try:
        import fiberpath.planning.planner  # noqa: F401
    except ImportError:
        return False
    return True


def helical(angle: float, lock: float = 540.0, lead_in: float = 10.0,
            lead_out: float = 30.0, pattern: int | None = None, skip: int | None = None
            ) -> dict[str, Any]:
    """A fiberpath helical layer (pattern/skip None: the first valid pair is searched)."""
    return {"windType": "helical", "windAngle": angle, "patternNumber": pattern,
            "skipIndex": skip, "lockDegrees": lock, "leadInMM": lead_in,
            "leadOutDegrees": lead_out}


HOOP: dict[str, Any] = {"windType": "hoop"}
TOW10 = {"width": 10.0, "thickness": 0.5}
TOW12 = {"width": 12.0, "thickness": 0.5}


@functools.lru_cache(maxsize=64)
def _plan(layers_key: str, mandrel_key: str, tow_key: str, feed: float) -> str:
    import json

    from fiberpath.config import WindDefinition
    from fiberpath.planning.exceptions import LayerValidationError
    from fiberpath.planning.planner import plan_wind

    layers, mandrel, tow = (json.loads(k) for k in (layers_key, mandrel_key, tow_key))
    resolved = []
    for layer in layers:
        if layer["windType"] != "helical" or layer["patternNumber"] is not None:
            resolved.append(layer)
            continue
        # fiberpath needs patternNumber to divide its circuit count and skipIndex coprime
        # to it: take the first pair (in a fixed order) that it accepts
        for pattern in range(2, 40):
            ok = None
            for skip in range(1, pattern):
                if math.gcd(pattern, skip) != 1:
                    continue
                trial = {**layer, "patternNumber": pattern, "skipIndex": skip}
                definition = WindDefinition.model_validate({
                    "schemaVersion": "1.3", "layers": [*resolved, trial],
                    "mandrelParameters": mandrel, "towParameters": tow,
                    "defaultFeedRate": feed})
                try:
                    plan_wind(definition)
                except LayerValidationError:
                    continue
                ok = trial
                break
            if ok is not None:
                resolved.append(ok)
                break
        else:
            raise ValueError(f"fiberpath accepts no pattern for layer {layer}")
    definition = WindDefinition.model_validate({
        "schemaVersion": "1.3", "layers": resolved, "mandrelParameters": mandrel,
        "towParameters": tow, "defaultFeedRate": feed})
    return "\n".join(plan_wind(definition).commands)


def fiberpath_gcode(layers: list[dict], mandrel: dict, tow: dict | None = None,
                    feed: float = 2000.0) -> str:
    """fiberpath's G-code for a wind definition (cached per definition)."""
    import json

    tow = tow or {"width": 8.0, "thickness": 0.5}
    return _plan(json.dumps(layers, sort_keys=True), json.dumps(mandrel, sort_keys=True),
                 json.dumps(tow, sort_keys=True), feed)


def gcode_points(text: str) -> np.ndarray:
    """[X mm, C deg] of a fiberpath program: X -> X, A -> C, B read and dropped."""
    res = read_gcode(text, axis_map={"X": "X", "A": "C", "B": "B"}, axes=["X", "C", "B"])
    return res.points[:, :2]


def _fp_entry(name: str, layers: list[dict], mandrel: dict, desc: str, *, fast: bool = False,
              long: bool = False, tow: dict | None = None) -> CorpusPath:
    radius = mandrel["diameter"] / 2.0
    cfg = winder_config(radius)

    def build(job: str) -> list:
        pts = gcode_points(fiberpath_gcode(layers, mandrel, tow))
        return point_segments(job, cfg.machine.axes, pts, CHUNK)

    params = {"kind": "fiberpath", "layers": layers, "mandrel": mandrel,
              "radius": radius, "B": "dropped"}
    return CorpusPath(name, "cam", cfg, build, notes=desc + "; fiberpath G-code, B dropped",
                      params=params, fast=fast, long=long)


def corpus() -> list[CorpusPath]:
    from bench.corpus import fiberpath_style

    if not fiberpath_available():
        return fiberpath_style.corpus(with_fiberpath=False)
    cyl = lambda d, length: {"diameter": d, "windLength": length}  # noqa: E731
    return [
        _fp_entry("cam-fp-hoop-D60-L80-noB", [HOOP], cyl(60, 80),
                  "hoop layer, D 60 L 80 mm", fast=True),
        _fp_entry("cam-fp-hel45-D30-L60-noB", [helical(45, lock=360)], cyl(30, 60),
                  "helical 45 deg, D 30 L 60 mm, tow 10 mm, lock 360 deg", tow=TOW10),
        _fp_entry("cam-fp-hel45-D60-L120-noB", [helical(45, lock=360)], cyl(60, 120),
                  "helical 45 deg, D 60 L 120 mm, lock 360 deg"),
        _fp_entry("cam-fp-hoop-hel45-D60-L150-noB", [HOOP, helical(45)], cyl(60, 150),
                  "hoop + helical 45 deg, D 60 L 150 mm"),
        _fp_entry("cam-fp-hel25-D120-L300-noB", [helical(25, lead_in=20)], cyl(120, 300),
                  "helical 25 deg, D 120 L 300 mm, tow 12 mm", tow=TOW12),
        _fp_entry("cam-fp-hel70-D50-L200-noB", [helical(70, lock=720, lead_out=60)],
                  cyl(50, 200), "helical 70 deg, D 50 L 200 mm, lock 720 deg"),
        _fp_entry("cam-fp-cone-hel40-D100to70-L200-noB", [helical(40)],
                  {"diameter": 100, "windLength": 200, "endDiameter": 70},
                  "cone D 100 -> 70 mm, L 200 mm, helical 40 deg"),
        _fp_entry("cam-fp-vonkarman-hel45-D100-L200-noB", [helical(45)],
                  {"diameter": 100, "windLength": 200, "profile": {"type": "vonKarman"}},
                  "von Karman nose D 100 L 200 mm, helical 45 deg"),
        _fp_entry("cam-fp-layers-D60-L150-noB",
                  [HOOP, helical(30), {"windType": "skip", "mandrelRotation": 90}, HOOP],
                  cyl(60, 150), "hoop, helical 30 deg, skip 90 deg, hoop: D 60 L 150 mm, "
                  "tow 10 mm", tow=TOW10),
        _fp_entry("cam-fp-long-101k-D100-L1400-noB", [HOOP, helical(30)], cyl(100, 1400),
                  "a long program (101k lines, ~550 s of motion): hoop + helical 30 deg on "
                  "D 100 L 1400 mm", long=True),
        *fiberpath_style.corpus(),
    ]
