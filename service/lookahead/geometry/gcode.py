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

Letters: `axis_map` (the machine configuration's `gcode.letters`) says which letter drives
which machine axis; a letter in `ignore` (`gcode.ignore`, `--ignore-letters`) is dropped
and counted (`GcodeResult.ignored`); any other axis letter is refused, naming the letter,
the line and the configuration key that would map it.

Feed (F, per minute, modal; path units per second in `GcodeResult.feed`, NaN = no cap).
What F measures depends on the `dialect`:
- `marlin` (what fiberpath writes): F is the feed in the machine's path metric (the
  Euclidean norm of the axis motion scaled by `path_scale`: on a winder the fibre speed over
  the mandrel surface, fiberpath's own "surface arc" time model), and G0 takes the modal F
  like G1. The cap is F / 60.
- `rs274` (LinuxCNC): G0 is a rapid with no cap; on G1, F applies to the linear axes'
  Euclidean length when any linear axis moves, else to the rotary axes' (deg/min). The
  cap in our metric is then F / 60 * (path length / F's length) of each move, so that the
  move takes the time the program says. We use this common reading of RS-274 (rather than
  F over all axes) because it is what LinuxCNC does and what CAM for it assumes.
G20 converts F by 25.4 where it measures linear axes. `GcodeResult.programmed_time_s` is
the program's own time estimate: each move's F length over F (moves without F, e.g. rs274
rapids, are not counted).

Path control (modal, as LinuxCNC): `G64 P<tol>` blends corners within tol (path units,
times 25.4 under G20), `G64` alone with the configured default tolerance, `G61` / `G61.1`
stop exactly at every corner. Each point carries the tolerance of the move that ends there
(`GcodeResult.tolerance`: NaN = the default, 0 = exact stop), for fits `linear` / `smooth`;
G-code input is fitted with `GCODE_FIT` unless a fit is asked for.
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
DIALECTS = ("marlin", "rs274")
#: the fit of G-code programs (G1 lines) when none is asked for: `smooth` follows dense
#: CAM output within the tolerance at the feed its curvature allows, and lines and corners
#: like `linear` (measured in bench/fidelity_bench.py)
GCODE_FIT = "smooth"


@dataclass(frozen=True)
class GcodeResult:
    """Points (n, naxes) in machine axes; per point: feed cap (path units/s, NaN = none)
    and source line (1-based); `skipped`: moves that did not move; `tolerance` per point:
    the corner tolerance in force (path units; NaN = the default, 0 = exact stop)."""

    axes: list[str]
    points: np.ndarray
    feed: np.ndarray
    lines: np.ndarray
    skipped: int
    tolerance: np.ndarray | None = None
    #: dropped words per ignored letter
    ignored: dict[str, int] | None = None
    #: the program's own estimate of its motion time at its F words (s)
    programmed_time_s: float = 0.0


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
    ignore: Sequence[str] = (),
    dialect: str = "marlin",
    path_scale: Sequence[float] | None = None,
) -> GcodeResult:
    """Parse `text`. axis_map: G-code letter -> machine axis (default X->X, A->C);
    axes: machine axis order of the output (default ["X", "C"]); ignore: letters to drop;
    dialect: "marlin" or "rs274" (see the module docstring); path_scale: the machine's path
    metric per axis (default 1 for every axis)."""
    if dialect not in DIALECTS:
        raise ValueError(f"dialect: unknown G-code dialect {dialect!r} (known: "
                         f"{', '.join(DIALECTS)})")
    axis_map = {k.upper(): v for k, v in (axis_map or {"X": "X", "A": "C"}).items()}
    axes = list(axes or ["X", "C"])
    col = {}
    for letter, axis in axis_map.items():
        if axis not in axes:
            raise ValueError(f"axis_map: {letter} -> {axis}, but {axis} is not in axes {axes}")
        if not (letter in _ROTARY or letter in _LINEAR):
            raise ValueError(f"axis_map: {letter} is not an axis letter")
        col[letter] = axes.index(axis)
    dropped = {letter.strip().upper(): 0 for letter in ignore}
    scale_path = np.ones(len(axes)) if path_scale is None else np.asarray(path_scale, float)
    linear_cols = [c for letter, c in col.items() if letter in _LINEAR]
    rotary_cols = [c for letter, c in col.items() if letter in _ROTARY]
    programmed_time = 0.0

    pos = np.zeros(len(axes))  # machine position, mm / deg
    offset = np.zeros(len(axes))  # machine = programmed * unit + offset
    motion, absolute, inches, feed = None, True, False, np.nan
    tolerance = np.nan  # G64 without P: the configured default
    points, feeds, lines, tols, skipped = [], [], [], [], 0
    for lineno, raw in enumerate(text.splitlines(), start=1):
        if raw.strip().startswith("%"):
            continue
        gcodes, targets, end, f_word, p_word = [], {}, False, None, None
        for letter, value in _words(raw, lineno):
            if letter == "N":
                continue
            if letter == "G":
                gcodes.append(value)
            elif letter == "M":
                if value not in (2, 30):
                    raise ValueError(f"line {lineno}: unsupported word M{value:g}")
                end = True
            elif letter == "P":
                p_word = value
            elif letter == "F":
                if not value > 0:
                    raise ValueError(f"line {lineno}: F must be > 0")
                f_word = value
            elif letter in col:
                if letter in targets:
                    raise ValueError(f"line {lineno}: {letter} given twice")
                targets[letter] = value
            elif letter in dropped:
                dropped[letter] += 1
            elif letter in _ROTARY or letter in _LINEAR:
                raise ValueError(
                    f"line {lineno}: letter {letter} ({letter}{value:g}): this machine has no "
                    f"axis for it; map it in the configuration (gcode.letters, e.g. "
                    f"\"{letter}:{letter}\" with an axis {letter} in machine.axes) or drop it "
                    f"(gcode.ignore = [\"{letter}\"], or --ignore-letters {letter})")
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
            elif g in (61, 61.1):
                tolerance = 0.0
            elif g == 64:
                if p_word is not None and not p_word >= 0:
                    raise ValueError(f"line {lineno}: G64 P must be >= 0")
                tolerance = np.nan if p_word is None else p_word * (
                    _MM_PER_INCH if inches else 1.0)
            elif g != 94:
                raise ValueError(f"line {lineno}: unsupported word G{g:g}")
        if p_word is not None and 64 not in gcodes:
            raise ValueError(f"line {lineno}: P is only read with G64")
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
                cap, seconds = _move_feed(new - pos, feed, motion, dialect, scale_path,
                                          linear_cols, rotary_cols)
                programmed_time += seconds
                points.append(new)
                feeds.append(cap)
                lines.append(lineno)
                tols.append(tolerance)
                pos = new
        if end:
            break
    return GcodeResult(
        axes=axes,
        points=np.array(points).reshape(-1, len(axes)),
        feed=np.array(feeds, dtype=float),
        lines=np.array(lines, dtype=int),
        skipped=skipped,
        tolerance=np.array(tols, dtype=float),
        ignored={k: v for k, v in dropped.items() if v},
        programmed_time_s=programmed_time,
    )


def _move_feed(delta: np.ndarray, feed: float, motion: int | None, dialect: str,
               path_scale: np.ndarray, linear: list[int], rotary: list[int]
               ) -> tuple[float, float]:
    """(path-speed cap in path units/s or NaN, the move's programmed time in s) of a move
    by `delta` (machine units) at modal `feed` (F / 60, per second, NaN = none yet)."""
    if np.isnan(feed) or (dialect == "rs274" and motion == 0):
        return np.nan, 0.0
    path_len = float(np.linalg.norm(delta * path_scale))
    if dialect == "marlin":
        return feed, path_len / feed
    moved_linear = [c for c in linear if delta[c] != 0.0]
    f_len = float(np.linalg.norm(delta[moved_linear if moved_linear else rotary]))
    if f_len == 0.0:  # only axes that F does not measure moved: no cap from F
        return np.nan, 0.0
    return feed * path_len / f_len, f_len / feed
