"""The finite-difference limit checker: the only judge of whether a setpoint stream obeys
the axis limits (PROTOCOL.md "Limits").

For sampled positions p[k] (axis units) at a fixed sample time dt (s), axis i obeys its
limits when, for every k,

    |p[k+1] - p[k]| / dt                         <= vmax[i]
    |p[k+2] - 2 p[k+1] + p[k]| / dt^2            <= amax[i]
    |p[k+3] - 3 p[k+2] + 3 p[k+1] - p[k]| / dt^3 <= jmax[i]

The checker knows nothing about planners. It is stateful: positions arrive in batches and
the differences that straddle a batch boundary are checked too; it keeps only the last 3
samples, so memory is O(1) in the stream length.

Tolerance (floating-point rounding only): a difference of order n is accepted when
|d_n| / dt^n <= limit * (1 + 1e-9) + 2^(n+1) * eps * max|p| / dt^n, where max|p| is the
largest position magnitude among the n+1 samples involved and eps the float64 machine
epsilon. The second term bounds the rounding error of evaluating the difference in float64
(its coefficients' absolute values sum to 2^n, each operation rounds by at most eps of an
operand of magnitude <= 2^n max|p|; one more factor 2 for safety). For positions of 1e5 deg at
dt = 1 ms that is 0.4 deg/s^3 on the jerk, negligible against any real limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from lookahead.limits import AxisLimits

KINDS = ("v", "a", "j")
_ORDER = {"v": 1, "a": 2, "j": 3}
_REL_TOL = 1e-9
_EPS = float(np.finfo(float).eps)


class Violation(NamedTuple):
    """One limit violation: the difference starting at sample k exceeds `limit` on `axis`."""

    k: int
    axis: int
    kind: str
    value: float
    limit: float


@dataclass
class CheckReport:
    """What the checker saw.

    counts[kind][i]: number of differences of that kind over the limit on axis i.
    peak_fraction[kind][i]: largest |difference| / limit seen on axis i (1.0 = at the limit).
    first: the earliest violation (smallest k), or None.
    """

    samples: int
    violations: int
    counts: dict[str, list[int]]
    peak_fraction: dict[str, list[float]]
    first: Violation | None = None
    extra: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.violations == 0

    def to_dict(self) -> dict:
        """Plain types only (for msgpack / JSON)."""
        return {
            "samples": self.samples,
            "violations": self.violations,
            "counts": {k: list(v) for k, v in self.counts.items()},
            "peak_fraction": {k: list(v) for k, v in self.peak_fraction.items()},
            "first": None if self.first is None else self.first._asdict(),
            "ok": self.ok,
        }


def _differences(p: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Finite differences of `order` along axis 0 and the max |p| over each stencil."""
    d = np.diff(p, n=order, axis=0)
    mag = np.abs(p)
    peak = mag[: len(p) - order].copy()
    for shift in range(1, order + 1):
        np.maximum(peak, mag[shift : len(p) - order + shift], out=peak)
    return d, peak


class LimitChecker:
    """Stateful finite-difference checker of a position stream (axis units, dt seconds)."""

    def __init__(self, limits: AxisLimits, dt: float) -> None:
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.limits = limits
        self.dt = float(dt)
        naxes = limits.naxes
        self._tail = np.empty((0, naxes))
        self._k0 = 0  # stream index of self._tail[0]
        self._n = 0
        self._counts = {k: np.zeros(naxes, dtype=np.int64) for k in KINDS}
        self._peak = {k: np.zeros(naxes) for k in KINDS}
        self._first: Violation | None = None

    def _limit(self, kind: str) -> np.ndarray:
        return {"v": self.limits.vmax, "a": self.limits.amax, "j": self.limits.jmax}[kind]

    def feed(self, pos_batch: np.ndarray) -> None:
        """Check the next samples, shape (n, naxes), in stream order."""
        batch = np.asarray(pos_batch, dtype=float)
        if batch.ndim == 1:
            batch = batch.reshape(1, -1)
        if batch.shape[1] != self.limits.naxes:
            raise ValueError(f"expected {self.limits.naxes} axes, got shape {batch.shape}")
        if len(batch) == 0:
            return
        if not np.all(np.isfinite(batch)):
            raise ValueError("positions must be finite")
        p = np.concatenate([self._tail, batch])
        self._n += len(batch)
        for kind in KINDS:
            order = _ORDER[kind]
            # differences already checked in earlier batches lie entirely inside the tail
            skip = max(len(self._tail) - order, 0)
            if len(p) <= order:
                continue
            d, mag = _differences(p[skip:], order)
            scale = self.dt**order
            value = np.abs(d) / scale
            limit = self._limit(kind)
            tol = limit * _REL_TOL + 2.0 ** (order + 1) * _EPS * mag / scale
            self._peak[kind] = np.maximum(self._peak[kind], np.max(value / limit, axis=0))
            over = value > limit + tol
            if over.any():
                self._counts[kind] += over.sum(axis=0)
                rows, cols = np.nonzero(over)
                k = self._k0 + skip + int(rows[0])
                if self._first is None or k < self._first.k:
                    axis = int(cols[0])
                    self._first = Violation(k, axis, kind, float(value[rows[0], axis]),
                                            float(limit[axis]))
        keep = min(3, len(p))
        self._k0 += len(p) - keep
        self._tail = p[len(p) - keep :].copy()

    def report(self) -> CheckReport:
        counts = {k: [int(c) for c in self._counts[k]] for k in KINDS}
        return CheckReport(
            samples=self._n,
            violations=int(sum(sum(c) for c in counts.values())),
            counts=counts,
            peak_fraction={k: [float(f) for f in self._peak[k]] for k in KINDS},
            first=self._first,
        )


def check_positions(pos: np.ndarray, limits: AxisLimits, dt: float) -> CheckReport:
    """Check a whole position stream (n, naxes) at once."""
    checker = LimitChecker(limits, dt)
    checker.feed(pos)
    return checker.report()
