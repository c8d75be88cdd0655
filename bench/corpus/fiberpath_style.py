"""Programs shaped like fiberpath's winding G-code, written here (no fiberpath needed):
G0 moves of X (mm) and A (deg) in 1 mm carriage steps along helical strokes, a lock at
each end where the mandrel turns `lock_deg` (~558 deg) with X held, a repeated line after
every lock (a zero-length move) and a `G92 A0` reset after every circuit (the reader
keeps the machine axis unwrapped). Read with `lookahead.geometry.gcode` (A -> C).
"""

from __future__ import annotations

import math

import numpy as np

from bench.corpus.base import CorpusPath, point_segments, rng_for, winder_config
from lookahead.geometry.gcode import read_gcode


def program(length: float, radius: float, alpha_deg: float, circuits: int,
            lock_deg: float = 558.0, step: float = 1.0, jitter: float = 0.0,
            seed_name: str = "") -> str:
    """The G-code text. jitter: random extra lock angle (deg, uniform 0..jitter, seeded)."""
    rng = rng_for(seed_name or "fiberpath-style")
    deg_per_mm = math.degrees(math.tan(math.radians(alpha_deg)) / radius)
    lines = ["G21", "G90", "G94", "G0 X0 A0", "G0 F6000"]
    a = 0.0
    n = round(length / step)
    for _ in range(circuits):
        for forward in (True, False):
            for i in range(1, n + 1):
                x = i * step if forward else length - i * step
                a += step * deg_per_mm
                lines.append(f"G0 X{x:.6g} A{a:.6f}")
            a += lock_deg + float(rng.uniform(0.0, jitter))
            lines.append(f"G0 X{0 if not forward else length:.6g} A{a:.6f}")
            lines.append(lines[-1])  # fiberpath repeats lines: a zero-length move
        lines.append("G92 A0")
        a = 0.0
    lines.append("M2")
    return "\n".join(lines)


def _entry(name: str, length: float, radius: float, alpha: float, circuits: int,
           fast: bool = False) -> CorpusPath:
    cfg = winder_config(radius)

    def build(job: str) -> list:
        res = read_gcode(program(length, radius, alpha, circuits, jitter=4.0, seed_name=name))
        return point_segments(job, cfg.machine.axes, np.asarray(res.points), 500)

    return CorpusPath(name, "cam", cfg, build,
                      notes=f"fiberpath-style program (written here): L {length:g} R "
                            f"{radius:g} mm, {alpha:g} deg, {circuits} circuits, 1 mm moves, "
                            "558 deg locks with X held, G92 resets, repeated lines",
                      params={"kind": "fiberpath-style", "length": length, "radius": radius,
                              "alpha_deg": alpha, "circuits": circuits}, fast=fast)


def corpus(with_fiberpath: bool = True) -> list[CorpusPath]:
    """Always two programs; without fiberpath, two more (so the family stays covered)."""
    out = [_entry("cam-style-R50-a45-L200", 200, 50, 45, 2, fast=True),
           _entry("cam-style-R100-a30-L600", 600, 100, 30, 3)]
    if not with_fiberpath:
        out += [_entry("cam-style-R150-a60-L400", 400, 150, 60, 3),
                _entry("cam-style-R30-a20-L300", 300, 30, 20, 2)]
    return out
