"""A small G-code reader for winder programs: G0/G1 moves of a linear carriage axis and a
rotary mandrel axis (X with A, or X with Y as the mandrel...), maybe a third axis.

Supported: G0, G1 (modal motion), G90/G91 (absolute/incremental, modal), G92 (set the
current position: an offset, non-modal), G20/G21 (inch/mm: inches convert the linear
letters X Y Z U V W by 25.4, never the rotary letters A B C), G94 (feed per minute, the
only feed mode), F (feed per minute, modal), N (line numbers, ignored), M2/M30 (program
end), comments `( ... )` and `; ...`, `%` lines. Anything else -> ValueError naming the
line. Positions before the first move are 0 on every axis (or what G92 set); the stream
starts at the first move's end point. Moves that end where the machine already is
(repeated lines, zero-length moves) are skipped and counted.

Feed: F on a G1 move becomes a cap on the path speed in path units per second (F / 60,
times 25.4 under G20); G0 moves carry no cap (NaN).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

_ROTARY = frozenset("ABC")
_LINEAR = frozenset("XYZUVW")
_WORD = re.compile(r"\s*([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
_COMMENT = re.compile(r"\([^()]*\)")
_MM_PER_INCH = 25.4


@dataclass(frozen=True)
class GcodeResult:
    """Points (n, naxes) in machine axes; per point: feed cap (path units/s, NaN = none)
    and source line (1-based); `skipped`: moves that did not move."""

    axes: list[str]
    points: np.ndarray
    feed: np.ndarray
    lines: np.ndarray
    skipped: int


def _words(line: str, lineno: int) -> list[tuple[str, float]]:
    text = _COMMENT.sub(" ", line.split(";", 1)[0])
    if "(" in text or ")" in text:
        raise ValueError(f"line {lineno}: unbalanced comment parenthesis")
    words, pos = [], 0
    for m in _WORD.finditer(text):
        if text[pos : m.start()].strip():
            break
        words.append((m.group(1).upper(), float(m.group(2))))
        pos = m.end()
    if text[pos:].strip():
        raise ValueError(f"line {lineno}: cannot read {text[pos:].strip()!r}")
    return words


def read_gcode(
    text: str,
    axis_map: Mapping[str, str] | None = None,
    axes: Sequence[str] | None = None,
) -> GcodeResult:
    """Parse `text`. axis_map: G-code letter -> machine axis (default X->X, A->C);
    axes: machine axis order of the output (default ["X", "C"])."""
    axis_map = {k.upper(): v for k, v in (axis_map or {"X": "X", "A": "C"}).items()}
    axes = list(axes or ["X", "C"])
    col = {}
    for letter, axis in axis_map.items():
        if axis not in axes:
            raise ValueError(f"axis_map: {letter} -> {axis}, but {axis} is not in axes {axes}")
        if not (letter in _ROTARY or letter in _LINEAR):
            raise ValueError(f"axis_map: {letter} is not an axis letter")
        col[letter] = axes.index(axis)

    pos = np.zeros(len(axes))  # machine position, mm / deg
    offset = np.zeros(len(axes))  # machine = programmed * unit + offset
    motion, absolute, inches, feed = None, True, False, np.nan
    points, feeds, lines, skipped = [], [], [], 0
    for lineno, raw in enumerate(text.splitlines(), start=1):
        if raw.strip().startswith("%"):
            continue
        gcodes, targets, end, f_word = [], {}, False, None
        for letter, value in _words(raw, lineno):
            if letter == "N":
                continue
            if letter == "G":
                gcodes.append(value)
            elif letter == "M":
                if value not in (2, 30):
                    raise ValueError(f"line {lineno}: unsupported word M{value:g}")
                end = True
            elif letter == "F":
                if not value > 0:
                    raise ValueError(f"line {lineno}: F must be > 0")
                f_word = value
            elif letter in col:
                if letter in targets:
                    raise ValueError(f"line {lineno}: {letter} given twice")
                targets[letter] = value
            else:
                raise ValueError(f"line {lineno}: unsupported word {letter}{value:g}")
        set_position = False
        for g in gcodes:
            if g in (0, 1):
                motion = int(g)
            elif g == 90:
                absolute = True
            elif g == 91:
                absolute = False
            elif g in (20, 21):
                inches = g == 20
            elif g == 92:
                set_position = True
            elif g != 94:
                raise ValueError(f"line {lineno}: unsupported word G{g:g}")
        if f_word is not None:
            feed = f_word / 60.0 * (_MM_PER_INCH if inches else 1.0)
        scale = {
            letter: (_MM_PER_INCH if inches and letter in _LINEAR else 1.0) for letter in targets
        }
        if set_position:
            if not targets:
                raise ValueError(f"line {lineno}: G92 needs at least one axis word")
            for letter, value in targets.items():
                offset[col[letter]] = pos[col[letter]] - value * scale[letter]
        elif targets:
            if motion is None:
                raise ValueError(f"line {lineno}: axis words before any G0/G1 motion mode")
            new = pos.copy()
            for letter, value in targets.items():
                i = col[letter]
                new[i] = value * scale[letter] + (offset[i] if absolute else pos[i])
            if np.array_equal(new, pos) and points:
                skipped += 1
            else:
                points.append(new)
                feeds.append(feed if motion == 1 else np.nan)
                lines.append(lineno)
                pos = new
        if end:
            break
    return GcodeResult(
        axes=axes,
        points=np.array(points).reshape(-1, len(axes)),
        feed=np.array(feeds, dtype=float),
        lines=np.array(lines, dtype=int),
        skipped=skipped,
    )
