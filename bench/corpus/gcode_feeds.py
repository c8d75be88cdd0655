"""G-code jobs whose F words cap the feed, sent exactly as `lookahead publish` sends a
G-code file (`lookahead_clients.job_source.make_segments`: 500 points a segment, the
reader's fit and corner tolerances, each segment's `feed` from its first point's F).

Every other corpus path runs at the machine's limits; these are the jobs where the
segment feeds, not the limits, set the speed, and where they change within a job (the
engine's look-ahead window follows the capped feed, `stream/engine.py`):

- fiberpath-style winding programs (`lookahead_clients.cam_program`, the shape of
  bench/long_program.py's 100k-line program) on the three-drive winder (X mm, C deg,
  B deg), at several F values, radii and angles;
- a 3-axis mill program: rounded-rectangle passes at a cutting feed, plunges at a slow
  feed, G0 rapids between them (no cap) and a finishing contour at a faster feed.

Units: mm, deg; F in mm/min (the reader turns it into path units per second).
"""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from typing import Any

from bench.corpus.base import CorpusPath, machine_config, rng_for
from bench.corpus.cnc import XYZ_LIMITS
from lookahead.config import Config, build_config
from lookahead.geometry.gcode import GCODE_FIT
from lookahead_clients.cam_program import WindingProgram, gcode
from lookahead_clients.job_source import gcode_source, make_segments

#: points per segment, as `lookahead publish` sends G-code by default
CHUNK = 500


def winder3_config(radius: float) -> Config:
    """The shipped three-drive winder (`machines/winder3.toml`) with C's path metric at
    mandrel radius `radius` (mm), and the planner's default method (the LP and the
    heuristic are both run by the bench)."""
    text = resources.files("lookahead.machines").joinpath("winder3.toml").read_text()
    raw: dict[str, Any] = tomllib.loads(text)
    raw["machine"]["path_scale"][1] = math.pi / 180.0 * radius
    raw.pop("planner", None)
    return build_config(raw, "<corpus>")


def _gcode_segments(job: str, cfg: Config, text: str) -> list:
    src = gcode_source(job, text, cfg.gcode_options())
    return make_segments(job, src.axes, src.points, CHUNK, src.fit or GCODE_FIT, src.feeds,
                         None, src.tolerances)


def _winding_entry(name: str, feed: float, length: float, radius: float, angle: float,
                   circuits: int, hoop: bool, fast: bool = False) -> CorpusPath:
    cfg = winder3_config(radius)
    prog = WindingProgram(length=length, radius=radius, angle_deg=angle, circuits=circuits,
                          hoop=hoop, feed_mm_min=feed)

    def build(job: str) -> list:
        return _gcode_segments(job, cfg, gcode(prog))

    return CorpusPath(
        name, "cam", cfg, build,
        notes=f"fiberpath-style G-code at F{feed:g} ({feed / 60:g} mm/s) on the three-drive "
              f"winder: L {length:g} R {radius:g} mm, {angle:g} deg, {circuits} circuits"
              + (", a hoop layer first" if hoop else "") + "; the feed cap, not the "
              "limits, sets the speed on the strokes",
        params={"kind": "gcode-feed", "feed_mm_min": feed, "length": length,
                "radius": radius, "alpha_deg": angle, "circuits": circuits, "hoop": hoop},
        fast=fast)


def mill_program(seed_name: str) -> str:
    """A pocketing program: 4 rounded-rectangle passes stepping down 1 mm at F1200, each
    entered by a plunge at F300 after a G0 rapid, then a finishing contour at F4800, with
    the corner radius and the pass size jittered (seeded)."""
    rng = rng_for(seed_name)
    lines = ["G21", "G90", "G94", "G0 X0 Y0 Z5"]

    def contour(w: float, h: float, r: float, feed: float) -> None:
        pts = []
        for cx, cy, a0 in ((w - r, r, -90.0), (w - r, h - r, 0.0), (r, h - r, 90.0),
                           (r, r, 180.0)):
            for k in range(9):
                a = math.radians(a0 + 90.0 * k / 8)
                pts.append((cx + r * math.cos(a), cy + r * math.sin(a)))
        pts.append(pts[0])
        lines.append(f"G1 X{pts[0][0]:.4f} Y{pts[0][1]:.4f} F{feed:g}")
        lines.extend(f"G1 X{x:.4f} Y{y:.4f}" for x, y in pts[1:])

    for depth in range(1, 5):
        w, h = 60.0 + float(rng.uniform(-5, 5)), 40.0 + float(rng.uniform(-5, 5))
        r = float(rng.uniform(3.0, 8.0))
        lines.append(f"G0 X{w - r:.4f} Y0 Z2")
        lines.append(f"G1 Z{-depth:g} F300")
        contour(w, h, r, 1200.0)
        lines.append("G0 Z5")
    lines.append("G0 X0 Y0")
    lines.append("G1 Z-4 F300")
    contour(70.0, 50.0, 10.0, 4800.0)
    lines += ["G0 Z5", "M2"]
    return "\n".join(lines) + "\n"


def _mill_entry(name: str, fast: bool = False) -> CorpusPath:
    lim = XYZ_LIMITS
    cfg = machine_config(["X", "Y", "Z"], ["mm"] * 3, [lim["vmax"]] * 3, [lim["amax"]] * 3,
                         [lim["jmax"]] * 3, machine_id="mill3")

    def build(job: str) -> list:
        return _gcode_segments(job, cfg, mill_program(name))

    return CorpusPath(
        name, "cnc", cfg, build,
        notes="3-axis pocketing G-code: passes at F1200, plunges at F300, G0 rapids (no "
              "cap), a finishing contour at F4800; feeds change within the job",
        params={"kind": "gcode-feed", "feeds_mm_min": [300, 1200, 4800]}, fast=fast)


def corpus() -> list[CorpusPath]:
    return [
        _winding_entry("cam-feed-w3-F6000-L150-R50-a45", 6000.0, 150.0, 50.0, 45.0, 1,
                       hoop=False, fast=True),
        _winding_entry("cam-feed-w3-F6000-L300-R100-a45-hoop", 6000.0, 300.0, 100.0, 45.0,
                       2, hoop=True),
        _winding_entry("cam-feed-w3-F1500-L200-R40-a60", 1500.0, 200.0, 40.0, 60.0, 2,
                       hoop=False),
        _winding_entry("cam-feed-w3-F20000-L500-R150-a30", 20000.0, 500.0, 150.0, 30.0, 1,
                       hoop=True),
        _mill_entry("cnc-feed-mill-pocket-mixed", fast=True),
    ]

