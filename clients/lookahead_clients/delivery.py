"""The sending side of PROTOCOL.md "Delivery", without a bus: which segment to put when.

`Outbox` keeps every segment of one job until the job ends and decides, from what the
service says, what the publisher puts next:

1. resends first: a seq named by a `missing` event goes out at once (the service takes a
   gap's segment in even while its buffer is full);
2. while the status shows `accepting`: segments the service turned away while full
   (`rejected` with `retry`), then new ones, as long as their seq is below
   `next_seq + window` (`next_seq` from a status whose `receiving` is this job);
3. a stall: if nothing progressed for `stall_s` (no higher `next_seq`, no `missing`) while
   segments the service may lack are out, the first STALL_RESEND unconfirmed ones from
   `next_seq` on are put again (duplicates are ignored by the service), with the wait
   doubling up to MAX_STALL_S. This recovers a lost tail, which no later segment reveals as a gap.

Test and demo options change only the first puts: `drop_rate` skips that fraction of them
(seeded), `reorder` shuffles them in blocks of that many, `duplicate` puts each twice.
Times are seconds on the caller's monotonic clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: segments in flight beyond the service's next_seq: PROTOCOL.md suggests "a few hundred";
#: 256 x 200-point segments are ~1 MB, and at the ~5 ms a status query takes on loopback
#: they keep >10k segments/s possible (bench/delivery_bench.py)
WINDOW = 256
#: no progress for this long with segments out: put the unconfirmed ones again (s); above
#: the service's 0.25 s repeat of `missing`, so that a gap is resent on request first
STALL_S = 1.0
MAX_STALL_S = 4.0
#: a stall puts at most this many unconfirmed segments again (a lost tail is short; a
#: service that is only slow must not get the whole window a second time)
STALL_RESEND = 16


@dataclass
class OutboxStats:
    """What one job's sending did (counts of puts)."""

    first_puts: int = 0
    dropped: int = 0  # first puts skipped on purpose (drop_rate)
    resent_missing: int = 0
    resent_refused: int = 0
    resent_stalled: int = 0
    refused: int = 0  # `rejected` with retry (buffer full)
    missing_events: int = 0
    status_updates: int = 0


class Outbox:
    """One job's segments (encoded payloads by seq) and what to put next; see the module
    docstring. Call `on_status` / `on_missing` / `on_refused` as messages arrive and
    `due(now_s)` for the puts to make now."""

    def __init__(self, job: str, payloads: list[bytes], window: int = WINDOW,
                 drop_rate: float = 0.0, seed: int | None = None, reorder: int = 0,
                 duplicate: bool = False, stall_s: float = STALL_S) -> None:
        if not payloads:
            raise ValueError("a job needs at least one segment")
        if not 0.0 <= drop_rate < 1.0:
            raise ValueError(f"drop rate must be in [0, 1), got {drop_rate}")
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        self.job = job
        self.payloads = payloads
        self.window = window
        self.duplicate = duplicate
        self.stats = OutboxStats()
        self._rng = np.random.default_rng(seed)
        self._drop_rate = drop_rate
        order = np.arange(len(payloads))
        if reorder > 1:
            for a in range(0, len(order), reorder):
                self._rng.shuffle(order[a:a + reorder])
        self._order = [int(s) for s in order]
        self._cursor = 0  # next first put in _order
        self._put_max = -1  # highest seq put (or dropped) at least once
        self.next_seq = 0  # the service's next_seq for this job (0 until it says)
        self.accepting = True
        self._resend: dict[int, None] = {}  # missing seqs, in the order they were named
        self._refused: set[int] = set()
        self._stall_s = stall_s
        self._stall_wait = stall_s
        self._progress_t: float | None = None

    # --- what the service says --------------------------------------------------------
    def on_status(self, receiving: str | None, next_seq: int | None, accepting: bool,
                  now_s: float) -> None:
        self.stats.status_updates += 1
        self.accepting = accepting
        if receiving == self.job and next_seq is not None and next_seq > self.next_seq:
            self.next_seq = min(next_seq, len(self.payloads))
            self._progressed(now_s)
            self._refused = {s for s in self._refused if s >= self.next_seq}

    def on_missing(self, seq: int, now_s: float) -> None:
        self.stats.missing_events += 1
        self._progressed(now_s)
        if 0 <= seq < len(self.payloads):
            self._resend[seq] = None

    def on_refused(self, seq: int) -> None:
        self.stats.refused += 1
        if 0 <= seq < len(self.payloads):
            self._refused.add(seq)

    def _progressed(self, now_s: float) -> None:
        self._progress_t = now_s
        self._stall_wait = self._stall_s

    # --- what to put ------------------------------------------------------------------
    @property
    def all_first_put(self) -> bool:
        return self._cursor >= len(self._order)

    @property
    def blocked(self) -> bool:
        """True if new segments wait for the window or for `accepting`."""
        if self.all_first_put:
            return False
        return not self.accepting or self._order[self._cursor] >= self.next_seq + self.window

    def due(self, now_s: float, new_allowed: int | None = None) -> list[bytes]:
        """The payloads to put now, in order (`new_allowed` caps new segments: pacing)."""
        if self._progress_t is None:
            self._progress_t = now_s
        out = []
        for seq in self._resend:
            out.append(self.payloads[seq])
            self.stats.resent_missing += 1
        self._resend.clear()
        if not self.accepting:
            return out
        limit = self.next_seq + self.window
        for seq in sorted(s for s in self._refused if s < limit):
            out.append(self.payloads[seq])
            self._refused.discard(seq)
            self.stats.resent_refused += 1
        budget = len(self._order) if new_allowed is None else new_allowed
        while budget > 0 and not self.all_first_put and self._order[self._cursor] < limit:
            seq = self._order[self._cursor]
            self._cursor += 1
            budget -= 1
            self._put_max = max(self._put_max, seq)
            self.stats.first_puts += 1
            if self._drop_rate and self._rng.random() < self._drop_rate:
                self.stats.dropped += 1
                continue
            out.append(self.payloads[seq])
            if self.duplicate:
                out.append(self.payloads[seq])
        if (self.next_seq <= self._put_max
                and now_s - self._progress_t >= self._stall_wait):
            # nothing moved: put the unconfirmed segments again
            for seq in range(self.next_seq,
                             min(self._put_max + 1, limit, self.next_seq + STALL_RESEND)):
                out.append(self.payloads[seq])
                self.stats.resent_stalled += 1
            self._progress_t = now_s
            self._stall_wait = min(2.0 * self._stall_wait, MAX_STALL_S)
        return out
