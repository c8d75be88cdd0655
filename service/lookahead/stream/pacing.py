"""Real-time pacing: when a batch is published, given the wall clock (passed in).

Sample k of a job is due at t0 + k*dt (t0: the job's start on the caller's monotonic
clock, seconds); a batch is published `lead_s` before its first sample is due. The first
batch of a job starts the clock: its sample 0 is due `lead_s` after it was produced.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Pacer:
    dt: float
    lead_s: float
    t0: float | None = None

    def start(self, now_s: float) -> None:
        """A new job's first batch is ready at now_s."""
        self.t0 = now_s + self.lead_s

    def due_s(self, k: int) -> float:
        """When sample k is due (the job must have started)."""
        assert self.t0 is not None
        return self.t0 + k * self.dt

    def publish_at(self, k0: int) -> float:
        """When a batch whose first sample is k0 should be published."""
        return self.due_s(k0) - self.lead_s

    def late_s(self, k0: int, now_s: float) -> float:
        """How late (>0) a batch published at now_s is against its first sample's due time."""
        return now_s - self.due_s(k0)
