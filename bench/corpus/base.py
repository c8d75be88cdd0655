"""The corpus entry (`CorpusPath`), machine configurations and segment builders shared by
the generator modules.

Units: axis units (mm, deg, or what the machine names), path units for arc length s (the
configuration's `path_scale` metric; mm for the winders).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lookahead.config import Config, build_config
from lookahead.geometry.base import Path
from lookahead.protocol import JOB_ID_RE, Segment
from lookahead.stream.assembler import JobGeometry

FAMILIES = ("winding", "cam", "cnc")
#: a path with more points (or control points) than this is "long": the bench can skip it
LONG_POINTS = 100_000


@dataclass
class CorpusPath:
    """One corpus job. `segments` are generated on first use (job id = `name`) and cached.

    name: unique, stable, a valid protocol job id. family: winding | cam | cnc.
    config: the machine it runs on. notes: what it is and what was simplified.
    params: the generator's parameters (radius mm, alpha deg, spacing mm, ...).
    fast: in the "fast" subset. long: 100k+ points (`--skip-long` skips it).
    """

    name: str
    family: str
    config: Config
    build: Callable[[str], list[Segment]] = field(repr=False)
    notes: str = ""
    params: dict[str, Any] = field(default_factory=dict)
    fast: bool = False
    long: bool = False
    _segments: list[Segment] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not JOB_ID_RE.match(self.name):
            raise ValueError(f"corpus name {self.name!r} is not a protocol job id")
        if self.family not in FAMILIES:
            raise ValueError(f"corpus family {self.family!r} not in {FAMILIES}")

    @property
    def segments(self) -> list[Segment]:
        """What a publisher sends for this job (generated once, then cached)."""
        if self._segments is None:
            self._segments = self.build(self.name)
        return self._segments

    @property
    def npoints(self) -> int:
        """Points (kind points) or control points (bspline/nurbs) over all segments."""
        return sum(len(s.points if s.kind == "points" else s.ctrl) for s in self.segments)

    def geometry(self) -> JobGeometry:
        """The job's geometry assembled by the service's own `JobGeometry` (finished)."""
        m = self.config.machine
        geo = JobGeometry(self.name, tuple(m.axes), np.asarray(m.path_scale),
                          self.config.planner.fit)
        for seg in self.segments:
            geo.add(seg)
        if not geo.finished:
            geo.truncate()
        return geo

    def path(self) -> Path:
        """The whole job's geometry as the service fits it."""
        path = self.geometry().path()
        if path is None:
            raise ValueError(f"{self.name}: the job has no motion")
        return path


def seed_of(name: str) -> int:
    """A stable per-path seed (crc32 of the name: independent of Python's hash salt)."""
    return zlib.crc32(name.encode("utf-8"))


def rng_for(name: str) -> np.random.Generator:
    return np.random.default_rng(seed_of(name))


# --- machines -----------------------------------------------------------------------------

#: limits of `default_config()` (the demo winder): X mm, C deg
WINDER_LIMITS = {"vmax": [500.0, 720.0], "amax": [2000.0, 3000.0], "jmax": [20000.0, 30000.0]}
#: a big winder (mandrels R >= 250 mm): the mandrel turns slowly
BIG_WINDER_LIMITS = {"vmax": [400.0, 120.0], "amax": [1500.0, 400.0],
                     "jmax": [15000.0, 4000.0]}


def winder_config(radius: float | None = None, big: bool = False, fit: str | None = None,
                  machine_id: str = "winder") -> Config:
    """An X (mm) / C (deg) winder; radius (mm) sets C's path_scale (pi/180 R), None keeps
    the default configuration's (R = 100 mm)."""
    machine: dict[str, Any] = {"id": machine_id, "axes": ["X", "C"], "units": ["mm", "deg"]}
    machine.update(BIG_WINDER_LIMITS if big else WINDER_LIMITS)
    if radius is not None:
        machine["path_scale"] = [1.0, math.pi / 180.0 * radius]
    raw: dict[str, Any] = {"machine": machine}
    if fit is not None:
        raw["planner"] = {"fit": fit}
    return build_config(raw, "<corpus>")


def machine_config(axes: Sequence[str], units: Sequence[str], vmax: Sequence[float],
                   amax: Sequence[float], jmax: Sequence[float],
                   path_scale: Sequence[float] | None = None, fit: str | None = None,
                   machine_id: str = "cnc", dt: float = 0.001) -> Config:
    """A general machine configuration (limits per axis, unit/s, unit/s^2, unit/s^3)."""
    machine: dict[str, Any] = {
        "id": machine_id, "axes": list(axes), "units": list(units),
        "vmax": [float(v) for v in vmax], "amax": [float(v) for v in amax],
        "jmax": [float(v) for v in jmax], "dt": float(dt),
        "path_scale": [1.0] * len(axes) if path_scale is None else [float(v) for v in
                                                                      path_scale]}
    raw: dict[str, Any] = {"machine": machine}
    if fit is not None:
        raw["planner"] = {"fit": fit}
    return build_config(raw, "<corpus>")


# --- segments -----------------------------------------------------------------------------


def point_segments(job: str, axes: Sequence[str], points: np.ndarray,
                   chunks: int | Sequence[int] = 200, fit: str = "cubic",
                   feed: float | None = None) -> list[Segment]:
    """`points` segments: consecutive chunks of one point stream (no repeated point between
    segments). chunks: a chunk size, or the sizes in turn (cycled)."""
    pts = np.asarray(points, dtype=float)
    sizes = [chunks] if isinstance(chunks, int) else [int(c) for c in chunks]
    if not sizes or min(sizes) < 1:
        raise ValueError("chunk sizes must be >= 1")
    bounds, a, i = [], 0, 0
    while a < len(pts):
        b = min(a + sizes[i % len(sizes)], len(pts))
        bounds.append((a, b))
        a, i = b, i + 1
    return [Segment(job, seq, tuple(axes), "points", last=seq == len(bounds) - 1,
                    points=pts[a:b], fit=fit, feed=feed)
            for seq, (a, b) in enumerate(bounds)]


@dataclass(frozen=True)
class Piece:
    """One B-spline (weights None) or NURBS curve piece: clamped knots, ctrl (m, naxes)."""

    degree: int
    knots: np.ndarray
    ctrl: np.ndarray
    weights: np.ndarray | None = None


def piece_segments(job: str, axes: Sequence[str], pieces: Sequence[Piece],
                   feed: float | None = None) -> list[Segment]:
    """`bspline` / `nurbs` segments, one per piece (each starts where the last ended)."""
    out = []
    for seq, p in enumerate(pieces):
        kind = "bspline" if p.weights is None else "nurbs"
        out.append(Segment(job, seq, tuple(axes), kind, last=seq == len(pieces) - 1,
                           degree=p.degree, knots=np.asarray(p.knots, dtype=float),
                           ctrl=np.asarray(p.ctrl, dtype=float),
                           weights=None if p.weights is None else np.asarray(p.weights,
                                                                             dtype=float),
                           feed=feed))
    return out


def clamped_knots(m: int, degree: int) -> np.ndarray:
    """A clamped uniform knot vector on [0, 1] for m control points."""
    inner = np.linspace(0.0, 1.0, m - degree + 1)
    return np.concatenate([[0.0] * degree, inner, [1.0] * degree])


def resample(curve: Callable[[np.ndarray], np.ndarray], spacing: float,
             path_scale: np.ndarray, dense: int | None = None,
             include_end: bool = True) -> np.ndarray:
    """Points of the parametric curve(t), t in [0, 1] (returns (n, naxes)), spaced
    `spacing` path units of arc length apart (the last step shorter), the end included.
    The arc length is integrated on `dense` parameter nodes (default: 8 per spacing)."""
    scale = np.asarray(path_scale, dtype=float)
    probe = curve(np.linspace(0.0, 1.0, 257))
    rough = float(np.sum(np.sqrt(np.sum((np.diff(probe, axis=0) * scale) ** 2, axis=1))))
    n_dense = dense or int(min(max(2000, 8 * rough / spacing), 4_000_000))
    t = np.linspace(0.0, 1.0, n_dense + 1)
    pts = curve(t)
    steps = np.sqrt(np.sum((np.diff(pts, axis=0) * scale) ** 2, axis=1))
    s = np.concatenate([[0.0], np.cumsum(steps)])
    total = s[-1]
    count = max(1, math.ceil(total / spacing - 1e-9))
    targets = np.arange(count) * spacing
    if include_end:
        targets = np.concatenate([targets, [total]])
    t_at = np.interp(targets, s, t)
    return curve(t_at)


def chain(parts: Sequence[np.ndarray]) -> np.ndarray:
    """Concatenate point runs that each start where the previous ended (its first point,
    a repeat, is dropped)."""
    out = [parts[0]]
    for p in parts[1:]:
        out.append(p[1:])
    return np.vstack(out)
