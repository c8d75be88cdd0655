"""Winding programs shaped like fiberpath's Marlin G-code, written here (no fiberpath
needed): for the three-drive demo, the tests and the long-program benchmark.

The program drives X (carriage, mm), A (mandrel, deg) and B (delivery head, deg), all with
`G0` under a modal `G0 F<feed>` as fiberpath writes them: an optional hoop layer (one
revolution in `hoop_steps` moves, X advancing one band width per revolution), then a
helical layer of `circuits` circuits, each two strokes in `step` mm carriage moves with the
eye B turned to +-(90 - angle) deg, a lock at each end where the mandrel turns `lock_deg`
with X held while B turns over, a repeated line after every lock (a zero-length move) and
a `G92 A0` after every circuit (the machine's mandrel axis stays unwrapped and grows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class WindingProgram:
    """What to write: mandrel length and radius (mm), winding angle (deg from the axis),
    circuits, lock angle (deg), carriage step (mm), feed (mm/min), hoop layer or not, band
    width (mm), moves per hoop revolution, and whether B (the delivery head) is written."""

    length: float = 300.0
    radius: float = 50.0
    angle_deg: float = 45.0
    circuits: int = 2
    lock_deg: float = 558.0
    step: float = 1.0
    feed_mm_min: float = 6000.0
    hoop: bool = True
    band: float = 10.0
    hoop_steps: int = 8
    delivery: bool = True


def _fmt(value: float) -> str:
    return f"{value:.4f}".rstrip("0").rstrip(".") or "0"


def gcode(prog: WindingProgram) -> str:
    """The program's text (one move a line)."""
    lines = ["; fiberpath-style winding program (lookahead_clients.cam_program)",
             "G21 ; millimeter units", "G90 ; absolute positioning",
             "G94 ; feed rate in units per minute", f"G0 F{_fmt(prog.feed_mm_min)}"]
    b_word = (lambda b: f" B{_fmt(b)}") if prog.delivery else (lambda b: "")
    lines.append("G0 X0 A0" + b_word(0.0))
    a = 0.0
    if prog.hoop:
        revolutions = max(1, math.floor(prog.length / prog.band))
        for i in range(1, revolutions * prog.hoop_steps + 1):
            a += 360.0 / prog.hoop_steps
            lines.append(f"G0 X{_fmt(i * prog.band / prog.hoop_steps)} A{_fmt(a)}")
        lines.append(f"G0 X0 A{_fmt(a + prog.lock_deg)}")  # back to the start, one move
        lines.append("G92 A0")
        a = 0.0
    eye = 90.0 - prog.angle_deg
    deg_per_mm = math.degrees(math.tan(math.radians(prog.angle_deg)) / prog.radius)
    n = max(1, round(prog.length / prog.step))
    for _ in range(prog.circuits):
        for forward in (True, False):
            b = eye if forward else -eye
            for i in range(1, n + 1):
                x = i * prog.step if forward else prog.length - i * prog.step
                a += prog.step * deg_per_mm
                lines.append(f"G0 X{_fmt(x)} A{_fmt(a)}" + b_word(b))
            a += prog.lock_deg
            lock = f"G0 X{_fmt(prog.length if forward else 0.0)} A{_fmt(a)}" + b_word(-b)
            lines += [lock, lock]  # fiberpath repeats lines: a zero-length move
        lines.append("G92 A0")
        a = 0.0
    lines.append("M2")
    return "\n".join(lines) + "\n"
