"""Per-job assembly of toolpath segments (PROTOCOL.md "Segment") into geometry.

`SegmentOrder` puts one job's segments in `seq` order and does the receiving side of
PROTOCOL.md "Delivery": an out-of-order segment waits (times in seconds on the caller's
clock), the seqs it waits for are announced as `missing`, a resend with the same content
(hash of the decoded fields) is ignored, one with different content is rejected.
`JobGeometry` turns the ordered segments into a `Path`: point streams through
`StreamingFit` (final geometry grows as points arrive), B-spline / NURBS pieces through
`CompositePath` (each piece is final when it arrives).
Arc lengths s are in the path metric (path units, mm for the winder).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from lookahead.geometry.base import Path
from lookahead.geometry.deviation import interval_excursions
from lookahead.geometry.fits import (
    TOLERANCE_FITS,
    AnyStreamingFit,
    extend_fit,
    make_streaming_fit,
)
from lookahead.geometry.nurbs import BSplinePath, CompositePath
from lookahead.geometry.polyline import DEFAULT_TOLERANCE
from lookahead.geometry.streaming import StreamingFit
from lookahead.planning.base import FeedCap
from lookahead.protocol import Segment

#: a segment's seq may lie at most this far beyond the job's next expected seq (a publisher
#: keeps a few hundred in flight; this stops a stray seq such as 2**64-1 from opening a gap
#: that nothing will fill)
SEQ_WINDOW = 65_536
#: `missing` is announced again this often while a seq is waited for (s): PROTOCOL.md asks
#: for at least every 0.5 s, and the service's loop may be busy ~0.1 s with a replan
MISSING_REPEAT_S = 0.25
#: at most this many missing seqs of one job are announced at a time (the lowest ones)
MAX_ANNOUNCED = 64
#: bytes counted per segment and per point on top of the segment's arrays (its objects and
#: the fit's state): tracemalloc measured 3.7-14.9 kB per 2-point cubic segment and
#: 0.95-2.2 kB per point of 200-point ones (cam-fp-hel25-D120-L300-noB, a sine; 2.2 kB with
#: the fits of issue 15; tests/test_delivery_engine.py checks that the estimate bounds the
#: measured memory). An overestimate only makes `accepting` turn false earlier.
SEGMENT_OVERHEAD_BYTES = 16 * 1024
POINT_OVERHEAD_BYTES = 3072
#: largest |coordinate x path_scale| taken in (path units): 1e12 mm is far beyond any
#: machine, and squares of it (arc lengths, spline solves) stay far from float overflow
MAX_COORDINATE = 1e12
#: a piece may start this far (relative to the axis range, at least 1 unit) from the last end
JOIN_TOL = 1e-9
#: at most this many fit-excursion warnings per job (one per segment at most)
MAX_WARNINGS = 20
#: a feed cap standing for "no cap" on segments without `feed` (path units / s)
NO_CAP = 1e12


class SegmentRejectedError(ValueError):
    """A segment that cannot be taken in; `reason` names the field and what is wrong."""

    def __init__(self, seq: int | None, reason: str) -> None:
        super().__init__(reason)
        self.seq = seq
        self.reason = reason


def segment_digest(seg: Segment) -> bytes:
    """A hash of everything a segment says (not of its payload bytes: a resend may be
    encoded differently, e.g. ints for floats, and is still the same segment)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(repr((seg.job, seg.seq, seg.axes, seg.kind, seg.last, seg.fit, seg.degree,
                   seg.feed, seg.tolerance)).encode())
    for arr in (seg.points, seg.knots, seg.ctrl, seg.weights):
        if arr is None:
            h.update(b"-")
        else:
            a = np.ascontiguousarray(arr, dtype="<f8")
            h.update(repr(a.shape).encode())
            h.update(a.tobytes())
    return h.digest()


def segment_size(seg: Segment) -> tuple[int, int]:
    """(points or control points, bytes) a segment takes in the service's buffer."""
    arrays = [a for a in (seg.points, seg.knots, seg.ctrl, seg.weights) if a is not None]
    n = len(seg.points) if seg.points is not None else len(seg.ctrl) if seg.ctrl is not None \
        else 0
    return n, (sum(int(a.nbytes) for a in arrays) + SEGMENT_OVERHEAD_BYTES
               + n * POINT_OVERHEAD_BYTES)


@dataclass
class _Waiting:
    seg: Segment
    digest: bytes
    t: float | None  # arrival time (s), None without a clock (replay)
    size: tuple[int, int]


@dataclass
class SegmentOrder:
    """Puts one job's segments in seq order. Times are seconds on the caller's clock."""

    job: str
    gap_timeout_s: float
    expected: int = 0
    last_seq: int | None = None
    pending: dict[int, _Waiting] = field(default_factory=dict)
    #: digests of the segments taken in, by seq (duplicates are recognised by them)
    taken: dict[int, bytes] = field(default_factory=dict)
    #: when each missing seq was last announced
    announced: dict[int, float] = field(default_factory=dict)
    pending_points: int = 0
    pending_bytes: int = 0
    _ready: dict[int, bytes] = field(default_factory=dict)

    def admission(self, seg: Segment) -> str:
        """What `offer` would do with `seg`, by seq alone: `duplicate` (a seq already
        here), `gap` (it fills a gap that later waiting segments sit behind) or `new`."""
        if seg.seq in self.taken or seg.seq in self.pending or seg.seq < self.expected:
            return "duplicate"
        if self.pending and self.expected <= seg.seq < max(self.pending):
            return "gap"
        return "new"

    def offer(self, seg: Segment, now_s: float | None) -> list[Segment]:
        """Segments ready in order after `seg` arrived (possibly none: it waits, or it is
        an identical duplicate, which is ignored). SegmentRejectedError if it conflicts."""
        digest = segment_digest(seg)
        known = self.taken.get(seg.seq)
        if known is None and seg.seq in self.pending:
            known = self.pending[seg.seq].digest
        if known is not None:
            if known == digest:
                return []
            raise SegmentRejectedError(seg.seq, f"seq: {seg.seq} of job {self.job!r} was "
                                       "already received with different content; the job "
                                       "goes on with the first")
        if self.last_seq is not None and seg.seq > self.last_seq:
            raise SegmentRejectedError(seg.seq, f"seq: {seg.seq} comes after the job's last "
                                       f"segment (seq {self.last_seq})")
        if seg.seq < self.expected:  # only after close(): the job ended at a timed-out gap
            raise SegmentRejectedError(seg.seq, f"seq: {seg.seq} of job {self.job!r} comes "
                                       "after the job ended")
        if seg.seq - self.expected >= SEQ_WINDOW:
            raise SegmentRejectedError(seg.seq, f"seq: {seg.seq} is {seg.seq - self.expected} "
                                       f"beyond the next expected seq {self.expected} of job "
                                       f"{self.job!r} (at most {SEQ_WINDOW - 1})")
        if seg.seq > self.expected:
            size = segment_size(seg)
            self.pending[seg.seq] = _Waiting(seg, digest, now_s, size)
            self.pending_points += size[0]
            self.pending_bytes += size[1]
            return []
        self._ready[seg.seq] = digest
        return [seg]

    def accepted(self, seg: Segment) -> list[Segment]:
        """Record that `seg` (the expected one) was taken in; the next waiting ones."""
        self.taken[seg.seq] = self._ready.pop(seg.seq)
        self.expected = seg.seq + 1
        if seg.last:
            self.last_seq = seg.seq
            for s in [s for s in self.pending if s > seg.seq]:
                self._unwait(s)
        return self.release()

    def refused(self, seg: Segment) -> None:
        """`seg` (offered as ready) could not be taken in: its seq stays missing."""
        self._ready.pop(seg.seq, None)

    def release(self) -> list[Segment]:
        nxt = self.pending.get(self.expected)
        if nxt is None:
            return []
        self._unwait(self.expected)
        self._ready[nxt.seg.seq] = nxt.digest
        return [nxt.seg]

    def _unwait(self, seq: int) -> None:
        w = self.pending.pop(seq)
        self.pending_points -= w.size[0]
        self.pending_bytes -= w.size[1]

    def holes(self, limit: int = MAX_ANNOUNCED) -> list[int]:
        """The lowest missing seqs (at most `limit`) below the highest waiting one."""
        if not self.pending:
            return []
        top = max(self.pending)
        out, s = [], self.expected
        while s < top and len(out) < limit:  # steps over waiting seqs or finds holes
            if s not in self.pending:
                out.append(s)
            s += 1
        return out

    def announce(self, now_s: float) -> list[int]:
        """Missing seqs to announce now: new holes, and holes announced MISSING_REPEAT_S
        ago or earlier."""
        holes = self.holes()
        due = [h for h in holes if now_s - self.announced.get(h, -np.inf) >= MISSING_REPEAT_S]
        keep = set(holes)
        self.announced = {h: t for h, t in self.announced.items() if h in keep}
        for h in due:
            self.announced[h] = now_s
        return due

    def overdue(self, now_s: float) -> bool:
        """True if a gap has been open (a later segment waiting) longer than the timeout."""
        times = [w.t for w in self.pending.values() if w.t is not None]
        return bool(times) and now_s - min(times) > self.gap_timeout_s

    def close(self) -> None:
        """No more segments: the last one taken in (seq expected - 1) ends the job, and
        waiting segments are dropped (a seq gap that timed out)."""
        self.last_seq = self.expected - 1
        for s in list(self.pending):
            self._unwait(s)
        self.announced.clear()

    @property
    def complete(self) -> bool:
        """True once the `last` segment and all before it are in."""
        return self.last_seq is not None and self.expected > self.last_seq

    @property
    def waiting(self) -> int:
        return len(self.pending)


class JobGeometry:
    """The geometry of one job, grown segment by segment (in seq order).

    `path()` is the best current Path (None before 2 distinct points); it never changes on
    [0, final_length]. `finished` once the `last` segment is in: then final_length is the
    whole path's length. `segment_ends_s()` gives the arc length at each segment's end.
    """

    def __init__(self, job: str, axes: tuple[str, ...], path_scale: np.ndarray,
                 default_fit: str = "cubic", default_tolerance: float = DEFAULT_TOLERANCE
                 ) -> None:
        self.job = job
        self.axes = axes
        self.path_scale = np.asarray(path_scale, dtype=float)
        self.default_fit = default_fit
        #: tolerance (path units) of segments that give none (`linear`, `smooth`; the
        #: excursion warnings of `cubic`, `pchip`)
        self.default_tolerance = default_tolerance
        #: warnings not yet drained (`drain_warnings`): fields of a `warning` event
        self.warnings: list[dict] = []
        self._warned = 0
        self._checked = 0  # knot intervals of the current fit checked for excursions
        self._checked_final: float | None = None  # its final_length at the last check
        self.kind: str | None = None
        self.finished = False
        self.nsegments = 0
        self.first_point: np.ndarray | None = None
        self._fit: AnyStreamingFit | None = None
        self._fit_method = default_fit
        self._pieces: list[Path] = []  # curve pieces, or frozen point fits
        self._composite: Path | None = None
        self._curve_length = 0.0
        # points: (index of the fit the segment ended in, chord u in that fit at its end)
        self._u_ends: list[tuple[int, float]] = []
        self._chord = 0.0  # chord length since the current fit's first point
        self._cached: tuple[Path | None, Path] | None = None
        self._last_point: np.ndarray | None = None
        self._lo: np.ndarray | None = None
        self._hi: np.ndarray | None = None
        self._feeds: list[float | None] = []
        #: bumped by every change of the geometry (`add`, `truncate`, `freeze`)
        self._version = 0
        #: ((scale, version), feed cap) of the last `feed_cap` call
        self._cap_memo: tuple[tuple[float, int], FeedCap | None] | None = None
        # running (points, bytes) totals after each taken-in segment
        self._cum_size: list[tuple[int, int]] = [(0, 0)]

    # --- input ----------------------------------------------------------------------
    def add(self, seg: Segment) -> None:
        """Take in the next segment; SegmentRejectedError leaves the geometry unchanged."""
        if self.finished:
            raise SegmentRejectedError(seg.seq, f"seq: job {self.job!r} already has its last "
                                  "segment")
        family = "points" if seg.kind == "points" else "curve"
        self._check_magnitude(seg)
        if self.kind is not None and family != self.kind:
            raise SegmentRejectedError(seg.seq, f"kind: job {self.job!r} is made of {self.kind} "
                                  f"segments, got {seg.kind!r}")
        if family == "points":
            self._add_points(seg)
        else:
            self._add_piece(seg)
        self.kind = family
        self.nsegments += 1
        self._version += 1
        self._feeds.append(seg.feed)
        n, b = segment_size(seg)
        total = self._cum_size[-1]
        self._cum_size.append((total[0] + n, total[1] + b))
        if seg.last:
            self.truncate()
        if family == "points":
            self._check_excursions(seg)

    def _check_magnitude(self, seg: Segment) -> None:
        """Reject coordinates so large that arc lengths and spline solves overflow."""
        name = "points" if seg.kind == "points" else "ctrl"
        arr = seg.points if seg.kind == "points" else seg.ctrl
        if arr is None or not len(arr):
            return
        big = np.abs(np.asarray(arr, dtype=float) * self.path_scale) > MAX_COORDINATE
        if big.any():
            i, j = np.argwhere(big)[0]
            raise SegmentRejectedError(seg.seq, f"{name}[{i}][{j}]: {arr[i, j]:.6g} is beyond "
                                       f"{MAX_COORDINATE:.0e} path units")

    def truncate(self) -> None:
        """End the job at what has been received: the `last` segment, or a seq gap that
        timed out. The path up to the end of what was received becomes final."""
        self.finished = True
        self._version += 1
        if self._fit is not None and self._fit.npoints >= 2:
            self._fit.finish()
            self._cached = None

    def _add_points(self, seg: Segment) -> None:
        assert seg.points is not None
        pts = np.asarray(seg.points, dtype=float)
        if seg.seq == 0:
            self._fit_method = seg.fit
            self.first_point = pts[0].copy()
        chain = pts if self._last_point is None else np.vstack([self._last_point, pts])
        fresh = self._fit is None
        fit = self._fit or make_streaming_fit(len(self.axes), self.path_scale,
                                              self._fit_method, self.default_tolerance)
        try:  # a fit started after a freeze begins at the frozen end point
            extend_fit(fit, chain if fresh else pts, seg.tolerance)
        except ValueError as exc:
            raise SegmentRejectedError(seg.seq, str(exc)) from None
        if fresh:
            self._checked = 0
            self._checked_final = None
        self._fit = fit
        self._cached = None
        steps = np.sqrt(np.sum((np.diff(chain, axis=0) * self.path_scale) ** 2, axis=1))
        self._chord += float(np.sum(steps))
        self._u_ends.append((len(self._pieces), self._chord))
        self._last_point = pts[-1].copy()

    def _check_excursions(self, seg: Segment) -> None:
        """`cubic` / `pchip`: a warning when the newly final pieces leave the points'
        polyline by more than the tolerance (at most one per segment, MAX_WARNINGS a job)."""
        fit = self._fit
        if fit is None or fit.method in TOLERANCE_FITS or fit.npoints < 2:
            return
        if self._warned >= MAX_WARNINGS:
            return
        if not fit.finished and fit.final_length == self._checked_final:
            return  # no new final pieces: skip building the live path (~3 ms a segment)
        self._checked_final = fit.final_length
        # the final pieces alone until the stream ends: the live path would also solve
        # and integrate the tail that the next points change (built per segment, ~3 ms)
        assert isinstance(fit, StreamingFit)  # the interpolating fits
        path = fit.path() if fit.finished else fit.final_path()
        if path is None:
            return
        k1 = len(path.pp.x) - 1
        if k1 <= self._checked:
            return
        tol = self.default_tolerance if seg.tolerance is None else seg.tolerance
        found = interval_excursions(path, fit.points(), self._checked, k1, tol)
        self._checked = k1
        if not found:
            return
        worst = max(found, key=lambda e: e.dev)
        offset = float(sum(p.length for p in self._pieces))
        self._warned += 1
        self.warnings.append({
            "seq": seg.seq, "s": offset + worst.s_max, "deviation": worst.dev,
            "tolerance": tol,
            "reason": f"fit: the {fit.method} fit leaves the points' polyline by up to "
                      f"{worst.dev:.6g} path units (tolerance {tol:g}) at s = "
                      f"{offset + worst.s_max:.6g} ({len(found)} stretch(es) up to segment "
                      f"{seg.seq}); fit linear or smooth follows it"})

    def drain_warnings(self) -> list[dict]:
        """The warnings since the last call (fields of `warning` events)."""
        out, self.warnings = self.warnings, []
        return out

    def freeze(self) -> bool:
        """Make the points received so far final (the publisher stalled): the current fit
        ends at the last point (where the machine will stop) and later points start a new
        fit there. False if there is nothing to freeze."""
        if self.finished or self._fit is None or self._fit.npoints < 2:
            return False
        if self._fit.final_length >= self._fit.path().length:
            return False
        self._pieces.append(self._fit.finish())
        self._fit = None
        self._chord = 0.0
        self._cached = None
        self._version += 1
        return True

    def _add_piece(self, seg: Segment) -> None:
        assert seg.ctrl is not None and seg.knots is not None
        try:
            piece = BSplinePath(seg.degree or 1, seg.knots, seg.ctrl, self.path_scale,
                                seg.weights)
        except ValueError as exc:
            raise SegmentRejectedError(seg.seq, str(exc)) from None
        if not piece.length > 0:
            raise SegmentRejectedError(seg.seq, "ctrl: the piece has zero length")
        start = piece.eval_u(np.array([piece.u_range[0]]), 0)[0, 0]
        end = piece.eval_u(np.array([piece.u_range[1]]), 0)[0, 0]
        if self._pieces:
            lo = np.minimum(self._lo, np.minimum(start, end))
            hi = np.maximum(self._hi, np.maximum(start, end))
            tol = JOIN_TOL * np.maximum(hi - lo, 1.0)
            gap = np.abs(start - self._last_point)
            if np.any(gap > tol):
                i = int(np.argmax(gap - tol))
                raise SegmentRejectedError(seg.seq, f"ctrl: the piece starts {gap[i]:.6g} "
                                      f"{self.axes[i]} away from the previous piece's end "
                                      "(pieces must join)")
        else:
            self.first_point = start.copy()
            lo, hi = np.minimum(start, end), np.maximum(start, end)
        # the composite is built lazily in path(): CompositePath evaluates every piece's
        # ends when built, so building it per piece costs O(pieces^2) over a job
        self._pieces.append(piece)
        self._composite = None
        self._curve_length += piece.length
        self._lo, self._hi = lo, hi
        self._last_point = end.copy()

    # --- output ---------------------------------------------------------------------
    def path(self) -> Path | None:
        if self.kind == "curve":
            if self._composite is None:  # pieces are checked to join in _add_piece
                self._composite = (self._pieces[0] if len(self._pieces) == 1
                                   else CompositePath(self._pieces, join_tol=JOIN_TOL))
            return self._composite
        live = self._fit.path() if self._fit is not None and self._fit.npoints >= 2 else None
        if not self._pieces:
            return live
        if self._cached is None or self._cached[0] is not live:
            pieces = self._pieces if live is None else [*self._pieces, live]
            self._cached = (live, pieces[0] if len(pieces) == 1 else CompositePath(pieces))
        return self._cached[1]

    @property
    def final_length(self) -> float:
        """Arc length up to which the geometry never changes again."""
        if self.kind == "curve":
            return self._curve_length
        done = float(sum(p.length for p in self._pieces))
        if self._fit is None or self._fit.npoints < 2:
            return done
        return done + (self._fit.path().length if self.finished else self._fit.final_length)

    @property
    def sent_length(self) -> float:
        """Arc length of everything received (the current best path's length)."""
        path = self.path()
        return 0.0 if path is None else path.length

    @property
    def empty(self) -> bool:
        """True when the job has no motion (fewer than two distinct points)."""
        return self.path() is None

    def segment_ends_s(self) -> np.ndarray:
        """Arc length (path units) at the end of each taken-in segment."""
        if self.kind == "curve":
            return np.cumsum([p.length for p in self._pieces])
        fits = list(self._pieces)
        if self._fit is not None and self._fit.npoints >= 2:
            fits.append(self._fit.path())
        offsets = np.concatenate([[0.0], np.cumsum([f.length for f in fits])])
        if not self._u_ends:
            return np.zeros(0)
        fit_of = np.array([j for j, _ in self._u_ends])
        u_end = np.array([u for _, u in self._u_ends])
        out = np.full(fit_of.size, offsets[-1])
        # one vectorized s_of_u per fit (the status asks for this at >= 5 Hz; one call per
        # segment cost 12 ms for a 236-segment layer)
        for j, f in enumerate(fits):
            mine = fit_of == j
            if np.any(mine):
                s_in = f.s_of_u(np.minimum(u_end[mine], f.u_range[1]))
                out[mine] = offsets[j] + np.minimum(s_in, f.length)
        return out

    def unexecuted_size(self, s_now: float | None, tol: float = 0.0) -> tuple[int, int]:
        """(points, bytes) of the taken-in segments that end beyond arc length `s_now`
        (all of them for None: a job that has not started)."""
        total = self._cum_size[-1]
        if s_now is None or len(self._cum_size) == 1:
            return total
        done = int(np.searchsorted(self.segment_ends_s(), s_now + tol, side="right"))
        executed = self._cum_size[done]
        return total[0] - executed[0], total[1] - executed[1]

    def feed_cap(self, scale: float = 1.0) -> FeedCap | None:
        """Per-segment `feed` caps times `scale` over s (None if no segment has one); the
        same object until a segment comes in, the path changes or `scale` does (the engine
        asks for it on every replan and every window decision)."""
        key = (scale, self._version)
        if self._cap_memo is None or self._cap_memo[0] != key:
            self._cap_memo = (key, self._feed_cap(scale))
        return self._cap_memo[1]

    def _feed_cap(self, scale: float) -> FeedCap | None:
        if all(f is None for f in self._feeds):
            return None
        ends = self.segment_ends_s()
        values = np.array([NO_CAP if f is None else f * scale for f in self._feeds])
        breaks = np.concatenate([[0.0], ends])
        keep = np.diff(breaks) > 0
        if not keep.any():
            return None
        breaks = np.concatenate([[0.0], ends[keep]])
        return FeedCap(breaks, values[keep])
