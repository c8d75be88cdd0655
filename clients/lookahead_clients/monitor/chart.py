"""The monitor's chart data: feed and |v|, |a|, |j| of each axis as a fraction of its limit,
computed from the setpoint batches' commanded positions by finite differences (PROTOCOL.md
"Limits", the same differences the checker judges) and decimated into fixed bins.

Each bin covers `bin_samples` consecutive samples (sample k is at job time k*dt, seconds)
and keeps the PEAK of every quantity in it, so decimation never hides a limit excursion.
Rows are kept in a ring of `capacity` bins, each with an increasing id for cursors.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

#: samples per chart bin: 20 ms at dt = 1 ms, 50 points per second of job time per line,
#: enough for a 10-30 s scrolling chart without sending the 1 kHz stream to the browser
BIN_SAMPLES = 20
#: bins kept per machine (60 s of job time at 20 ms bins)
CAPACITY = 3000


@dataclass
class ChartRow:
    """One bin: `t` (s, job time of its last sample), `feed` (peak path speed, path units/s),
    `v`, `a`, `j` (peak |derivative| / limit per axis, dimensionless), `pos` (axis
    positions at its last sample, axis units)."""

    id: int
    t: float
    feed: float
    v: list[float]
    a: list[float]
    j: list[float]
    pos: list[float]

    def to_json(self) -> dict:
        return {"id": self.id, "t": round(self.t, 6), "feed": round(self.feed, 4),
                "v": [round(x, 5) for x in self.v], "a": [round(x, 5) for x in self.a],
                "j": [round(x, 5) for x in self.j], "pos": [round(x, 6) for x in self.pos]}


class ChartBinner:
    """Turns one job's positions (axis units, in sample order) into `ChartRow`s.

    `vmax`, `amax`, `jmax`: per-axis limits; `path_scale`: per-axis factor of the path-speed
    metric (PROTOCOL.md "Path speed"); `dt`: sample time (s)."""

    def __init__(self, vmax, amax, jmax, path_scale, dt: float,
                 bin_samples: int = BIN_SAMPLES, capacity: int = CAPACITY) -> None:
        self.limits = np.array([vmax, amax, jmax], dtype=float)  # (3, naxes)
        self.scale = np.asarray(path_scale, dtype=float)
        self.dt = float(dt)
        self.bin_samples = int(bin_samples)
        self.rows: deque[ChartRow] = deque(maxlen=capacity)
        self.next_id = 0
        #: job-wide peaks of |v|, |a|, |j| / limit seen by the monitor, (3, naxes)
        self.peak = np.zeros_like(self.limits)
        self.samples = 0
        self.gaps = 0
        self._tail = np.empty((0, self.scale.size))  # last <= 3 positions before _next_k
        self._next_k: int | None = None
        self._acc: np.ndarray | None = None  # open bin: [feed, v..., a..., j...] peaks
        self._acc_bin = -1
        self._acc_last: tuple[float, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the job (a new job starts); the ring keeps its rows, ids keep growing."""
        self.peak[:] = 0.0
        self.samples = 0
        self.gaps = 0
        self._tail = np.empty((0, self.scale.size))
        self._next_k = None
        self._flush()

    def add(self, k0: int, pos: np.ndarray) -> list[ChartRow]:
        """Add samples k0 .. k0+n-1 (positions (n, naxes)); returns the bins it closed.

        A k0 other than the next expected sample index counts as a gap: the differences
        restart after it (none is computed across the gap)."""
        pos = np.asarray(pos, dtype=float)
        n = pos.shape[0]
        if n == 0:
            return []
        if self._next_k is not None and k0 != self._next_k:
            self.gaps += 1
            self._tail = np.empty((0, self.scale.size))
        p = np.vstack([self._tail, pos])
        m = self._tail.shape[0]  # samples of p before k0
        ks = np.arange(k0, k0 + n)
        deriv = np.zeros((3, n, self.scale.size))
        have = np.zeros((3, n), dtype=bool)
        for order in range(1, 4):
            d = np.diff(p, n=order, axis=0) / self.dt ** order  # ends at p[order:]
            first = order - m  # index into the new samples of d's first row
            lo = max(first, 0)
            deriv[order - 1, lo:] = np.abs(d[lo - first:])
            have[order - 1, lo:] = True
        frac = deriv / self.limits[:, None, :]
        frac[~have] = 0.0
        self.peak = np.maximum(self.peak, frac.max(axis=1))
        feed = np.linalg.norm(deriv[0] * self.scale, axis=1)
        feed[~have[0]] = 0.0
        self.samples += n
        self._tail = p[-3:]
        self._next_k = k0 + n
        values = np.hstack([feed[:, None], frac[0], frac[1], frac[2]])  # (n, 1 + 3 naxes)
        return self._bin(ks, values, pos)

    def _bin(self, ks: np.ndarray, values: np.ndarray, pos: np.ndarray) -> list[ChartRow]:
        closed: list[ChartRow] = []
        bins = ks // self.bin_samples
        starts = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
        peaks = np.maximum.reduceat(values, starts, axis=0)
        ends = np.r_[starts[1:], len(ks)] - 1
        for b, peak, end in zip(bins[starts], peaks, ends, strict=True):
            if self._acc is not None and b != self._acc_bin:
                closed.extend(self._flush())
            self._acc = peak if self._acc is None else np.maximum(self._acc, peak)
            self._acc_bin = int(b)
            self._acc_last = (float(ks[end] * self.dt), pos[end])
            if (ks[end] + 1) % self.bin_samples == 0:  # the bin is full
                closed.extend(self._flush())
        return closed

    def close(self) -> list[ChartRow]:
        """Close the open bin (the job's last samples)."""
        return self._flush()

    def _flush(self) -> list[ChartRow]:
        if self._acc is None or self._acc_last is None:
            self._acc = None
            return []
        na = self.scale.size
        t, last = self._acc_last
        acc = self._acc
        row = ChartRow(self.next_id, t, float(acc[0]), acc[1:1 + na].tolist(),
                       acc[1 + na:1 + 2 * na].tolist(), acc[1 + 2 * na:].tolist(),
                       np.asarray(last, dtype=float).tolist())
        self.next_id += 1
        self.rows.append(row)
        self._acc = None
        self._acc_last = None
        return [row]

    def since(self, cursor: int) -> list[ChartRow]:
        """Rows with id >= cursor still in the ring, oldest first."""
        if not self.rows or cursor > self.rows[-1].id:
            return []
        start = max(cursor - self.rows[0].id, 0)
        return [self.rows[i] for i in range(start, len(self.rows))]
