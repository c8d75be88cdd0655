"""A job's point stream from a winding preset, a points file (CSV/.npy) or G-code, and its
split into `points` segments (PROTOCOL.md: consecutive chunks of one stream, no repeated
points between segments)."""

from __future__ import annotations

import itertools
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lookahead.protocol import Segment

GCODE_SUFFIXES = (".gcode", ".nc", ".ngc", ".tap", ".g")


@dataclass(frozen=True)
class JobSource:
    """Points (n, naxes) in machine axes; `feeds` (n,) path-speed caps (units/s, NaN =
    none) or None; a one-line description; for G-code, the fit it is streamed with by
    default (`GCODE_FIT`) and the corner tolerance in force at each point (path units,
    NaN = the machine's default, 0 = exact stop; from G64 P / G61)."""

    name: str
    axes: list[str]
    points: np.ndarray
    feeds: np.ndarray | None
    description: str
    fit: str | None = None
    tolerances: np.ndarray | None = None


def load_job(source: str, axes: list[str], circuits: int | str | None = None,
             gcode_options: dict | None = None) -> JobSource:
    """Resolve `source`: a preset name (`tube-1450`, `tube-9570`), else a file by suffix.
    `gcode_options`: keyword arguments of `read_gcode` (`Config.gcode_options`: the machine's
    letters, dropped letters, dialect, path metric); default: `axes` only."""
    from lookahead.geometry.winding import PRESETS, preset_points

    if source in PRESETS:
        preset_axes, points, info = preset_points(source, circuits)
        if list(preset_axes) != list(axes):
            raise ValueError(f"preset {source} has axes {preset_axes}, the machine {axes}")
        return JobSource(source, list(axes), points, None, info.description)
    path = Path(source)
    if not path.is_file():
        raise ValueError(f"{source}: neither a preset ({', '.join(PRESETS)}) nor a file")
    if path.suffix.lower() in GCODE_SUFFIXES:
        return gcode_source(path.stem, path.read_text(encoding="utf-8"),
                            gcode_options or {"axes": axes}, path.name)
    from lookahead.geometry.files import load_points_file

    file_axes, points = load_points_file(path, axes)
    return JobSource(path.stem, list(file_axes), points, None,
                     f"points file {path.name}: {len(points)} points")


def gcode_source(name: str, text: str, gcode_options: dict, filename: str | None = None
                 ) -> JobSource:
    """A G-code program's text as a job: `read_gcode` with `gcode_options`
    (`Config.gcode_options`), streamed with the G-code fit (`GCODE_FIT`), the F words as
    feed caps and the corner tolerances in force."""
    from lookahead.geometry.gcode import GCODE_FIT, read_gcode

    res = read_gcode(text, **gcode_options)
    dropped = "".join(f"; dropped {n} {letter} word(s): no drive for letter {letter}"
                      for letter, n in (res.ignored or {}).items())
    return JobSource(name, list(res.axes), res.points, res.feed,
                     f"G-code {filename or name}: {len(res.points)} points "
                     f"({res.skipped} zero-length moves skipped{dropped}); the program "
                     f"says {res.programmed_time_s:.1f} s at its F words",
                     fit=GCODE_FIT, tolerances=res.tolerance)


def default_job_id(name: str) -> str:
    """`<name>-<unix time in ms>`, reduced to the protocol's job-id alphabet."""
    stem = re.sub(r"[^A-Za-z0-9_.-]", "_", name)[:40] or "job"
    return f"{stem}-{int(time.time() * 1000)}"


def _chunks(n: int, chunk: int, *per_point: np.ndarray | None) -> list[tuple[int, int]]:
    """[start, stop) point ranges of at most `chunk` points, also cut where a per-point
    value (feed cap, tolerance; NaN = none) changes, so each segment's value is exact."""
    cuts = {0, n}
    for values in per_point:
        if values is not None and n > 1:
            f = np.where(np.isnan(values), -1.0, values)
            cuts.update(int(i) + 1 for i in np.flatnonzero(f[1:] != f[:-1]))
    out = []
    bounds = sorted(cuts)
    for a, b in itertools.pairwise(bounds):
        out.extend((s, min(s + chunk, b)) for s in range(a, b, chunk))
    return out


def make_segments(job: str, axes: list[str], points: np.ndarray, chunk: int = 500,
                  fit: str = "cubic", feeds: np.ndarray | None = None,
                  feed: float | None = None, tolerances: np.ndarray | None = None
                  ) -> list[Segment]:
    """`points` segments of at most `chunk` points each. `feeds` (per point, NaN = none)
    caps each segment's path speed; `feed` caps the whole job (the smaller cap wins);
    `tolerances` (per point, NaN = the machine's default) become the segments'
    `tolerance`."""
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    pts = np.asarray(points, dtype=float)
    ranges = _chunks(len(pts), chunk, feeds, tolerances)
    segments = []
    for seq, (a, b) in enumerate(ranges):
        caps = [c for c in (feed, None if feeds is None else float(feeds[a])) if c is not None
                and np.isfinite(c)]
        tol = None if tolerances is None or np.isnan(tolerances[a]) else float(tolerances[a])
        segments.append(Segment(job, seq, tuple(axes), "points", last=seq == len(ranges) - 1,
                                points=pts[a:b], fit=fit, feed=min(caps) if caps else None,
                                tolerance=tol))
    return segments
