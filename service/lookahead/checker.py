"""The finite-difference limit checker: the only judge of whether a setpoint stream obeys
the axis limits (PROTOCOL.md "Limits").

For sampled positions p[k] (axis units) at a fixed sample time dt (s), axis i obeys its
limits when, for every k,

    |p[k+1] - p[k]| / dt                         <= vmax[i]
    |p[k+2] - 2 p[k+1] + p[k]| / dt^2            <= amax[i]
    |p[k+3] - 3 p[k+2] + 3 p[k+1] - p[k]| / dt^3 <= jmax[i]

The checker knows nothing about planners. It is stateful: positions arrive in batches and
the differences that straddle a batch boundary are checked too; it keeps the last 3
samples and at most FLUSH_ROWS samples not checked yet (small batches are checked
together, at the latest by `report()`: the same differences, so the same report), so
memory is O(1) in the stream length.

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
#: fed samples are checked once this many are waiting (or at `report()`): trades this
#: much memory (rows x axes floats) for the per-call cost of ~30 numpy operations, which
#: dominated a service-sized batch of 10 samples (~90 us of ~100 us a batch)
FLUSH_ROWS = 1000


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
        self._first: Violation | None = None
        self._pending: list[np.ndarray] = []  # fed, not checked yet (FLUSH_ROWS)
        self._pending_rows = 0
        # per order 1, 2, 3 (v, a, j): limits (3, naxes, 1: the differences are checked
        # axis by axis along the samples, `_flush`), dt^n, the rounding coefficient
        # 2^(n+1) eps (module docstring) and the largest |difference| / limit seen per axis
        self._lim3 = np.stack([self._limit(k) for k in KINDS])[:, :, None]
        self._scale3 = np.array([self.dt**n for n in (1, 2, 3)])[:, None, None]
        self._coef3 = np.array([2.0 ** (n + 1) * _EPS for n in (1, 2, 3)])[:, None, None]
        self._peak3 = np.zeros((3, naxes))

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
        if not np.isfinite(batch).all():
            raise ValueError("positions must be finite")
        self._pending.append(batch.copy())
        self._pending_rows += len(batch)
        if self._pending_rows >= FLUSH_ROWS:
            self._flush()

    def _flush(self) -> None:
        """Check the samples fed since the last check."""
        if not self._pending:
            return
        batch = self._pending[0] if len(self._pending) == 1 else np.concatenate(self._pending)
        self._pending, self._pending_rows = [], 0
        p = np.concatenate([self._tail, batch])
        self._n += len(batch)
        ntail = len(self._tail)
        # the differences of order 1, 2, 3 as repeated first differences (what np.diff
        # does for n > 1) and the largest |p| over each stencil, computed once for the three
        # orders (the same values as per order: both are elementwise). Axis by axis along
        # the samples (naxes, n): numpy reduces over a long contiguous axis several times
        # faster than over the rows of a few axes (the peaks; the same values)
        q = np.ascontiguousarray(p.T)
        d = q
        mag = np.abs(q)
        peak = mag
        diffs, peaks = [], []
        for order in (1, 2, 3):
            if len(p) <= order:
                break
            d = d[:, 1:] - d[:, :-1]
            peak = np.maximum(peak[:, :-1], mag[:, order:])
            # differences already checked in earlier batches lie entirely inside the tail
            skip = max(ntail - order, 0)
            diffs.append(d[:, skip:])
            peaks.append(peak[:, skip:])
        if ntail == 3:
            # a full tail (every batch after the first): each order has one difference per
            # new sample, so the three orders are checked as one (3, n, naxes) array
            self._check_stacked(np.stack(diffs), np.stack(peaks))
        else:
            for i, (dd, pk) in enumerate(zip(diffs, peaks, strict=True)):
                self._check(KINDS[i], i + 1, dd, pk, max(ntail - i - 1, 0))
        keep = min(3, len(p))
        self._k0 += len(p) - keep
        self._tail = p[len(p) - keep :].copy()

    def _check_stacked(self, d: np.ndarray, mag: np.ndarray) -> None:
        """`_check` of the three orders at once: d, mag (3, naxes, n), the differences of
        order 1, 2, 3 starting at stream samples k0 + 2, k0 + 1, k0 (a tail of 3). The same
        operations elementwise as `_check`, so the same counts, peaks and first violation.
        The peak is max(|d| / dt^n) / limit: dividing by a positive number is monotone in
        floating point, so it equals the largest quotient exactly."""
        value = np.abs(d) / self._scale3
        tol = self._lim3 * _REL_TOL + self._coef3 * mag / self._scale3
        self._peak3 = np.maximum(self._peak3, np.max(value, axis=2) / self._lim3[:, :, 0])
        over = value > self._lim3 + tol
        if over.any():
            for i in np.flatnonzero(over.any(axis=(1, 2))):
                self._record(KINDS[i], over[i], value[i], 2 - int(i))

    def _check(self, kind: str, order: int, d: np.ndarray, mag: np.ndarray, skip: int) -> None:
        """Count and record the differences `d` (naxes, n) of `order` (stencil maxima
        `mag`) over the limit; column 0 of d starts at stream sample self._k0 + skip."""
        i = order - 1
        scale = self._scale3[i, 0, 0]
        value = np.abs(d) / scale
        limit = self._lim3[i]
        tol = limit * _REL_TOL + self._coef3[i, 0, 0] * mag / scale
        self._peak3[i] = np.maximum(self._peak3[i], np.max(value, axis=1) / limit[:, 0])
        over = value > limit + tol
        if over.any():
            self._record(kind, over, value, skip)

    def _record(self, kind: str, over: np.ndarray, value: np.ndarray, skip: int) -> None:
        """Count the violations `over` (naxes, n: columns from stream sample k0 + skip) of
        `kind`."""
        self._counts[kind] += over.sum(axis=1)
        rows, cols = np.nonzero(over.T)  # by sample, then by axis
        k = self._k0 + skip + int(rows[0])
        if self._first is None or k < self._first.k:
            axis = int(cols[0])
            self._first = Violation(k, axis, kind, float(value[axis, rows[0]]),
                                    float(self._limit(kind)[axis]))

    def report(self) -> CheckReport:
        self._flush()
        counts = {k: [int(c) for c in self._counts[k]] for k in KINDS}
        return CheckReport(
            samples=self._n,
            violations=int(sum(sum(c) for c in counts.values())),
            counts=counts,
            peak_fraction={k: [float(f) for f in self._peak3[i]] for i, k in enumerate(KINDS)},
            first=self._first,
        )


def check_positions(pos: np.ndarray, limits: AxisLimits, dt: float) -> CheckReport:
    """Check a whole position stream (n, naxes) at once."""
    checker = LimitChecker(limits, dt)
    checker.feed(pos)
    return checker.report()
