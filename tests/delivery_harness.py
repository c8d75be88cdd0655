"""Helpers for the delivery tests: our publisher (`publish_job`) in a thread against a
`service_harness.Harness`, and a way to make a job's setpoints independent of when its
segments arrived (so that a lossy run can be compared bit for bit with a lossless one)."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np

from lookahead.bus import free_tcp_endpoint, with_endpoints
from lookahead.config import Config
from lookahead.protocol import Segment, SetpointBatch, Status
from lookahead_clients.job_source import make_segments
from service_harness import Harness


def bus_config(base: Config, method: str = "heuristic", **service) -> Config:
    """`base` on a free loopback port, with the planner `method` and service overrides."""
    return replace(base, zenoh=with_endpoints(base.zenoh, listen=[free_tcp_endpoint()]),
                   planner=replace(base.planner, method=method),
                   service=replace(base.service, **service))


class PublisherThread:
    """`publish_job(cfg, segments, **kw)` in a daemon thread; `rc` and `stats` after join."""

    def __init__(self, cfg: Config, segments: list[Segment], **kw) -> None:
        from lookahead_clients.publisher import publish_job

        self.rc: int | None = None
        self.stats: dict = {}
        self.messages: list[str] = []

        def run() -> None:
            self.rc = publish_job(cfg, segments, say=self.messages.append, progress=False,
                                  stats=self.stats, **kw)

        self.thread = threading.Thread(target=run, daemon=True)
        self.thread.start()

    def join(self, timeout: float) -> int:
        self.thread.join(timeout)
        assert not self.thread.is_alive(), f"the publisher did not end: {self.messages}"
        assert self.rc is not None
        return self.rc


def status(h: Harness) -> Status:
    return Status.decode(h.status_bytes())


def rechunk(segments: list[Segment], job: str, chunk: int) -> list[Segment]:
    """The point stream of `segments` (kind points) cut into segments of `chunk` points."""
    pts = np.vstack([s.points for s in segments])
    return make_segments(job, list(segments[0].axes), pts, chunk, segments[0].fit)


def lead_in(job: str, here: np.ndarray, to: np.ndarray, axes) -> tuple[Segment, Segment]:
    """A two-segment job from `here` to `to` through an offset middle point: the first
    segment (not `last`) makes the machine move and starve, the second ends the job."""
    mid = (here + to) / 2.0 + 5.0
    first = Segment(job, 0, tuple(axes), "points", False, points=np.vstack([here, mid]))
    second = Segment(job, 1, tuple(axes), "points", True, points=to.reshape(1, -1))
    return first, second


def deliver_then_run(h: Harness, segments: list[Segment], here: np.ndarray, tag: str,
                     timeout: float = 60.0, **publish) -> tuple[list[SetpointBatch],
                                                                 PublisherThread]:
    """Run `segments` (one job) so that it starts only once all of it is in.

    A lead-in job from `here` to the job's first point runs and starves (it stays the
    active job); meanwhile our publisher sends the job with the `publish` options (drops,
    reorders, duplicates). When the service's status says the job is complete
    (`receiving` it with `next_seq` = its segment count), the lead-in's last segment goes
    out, the lead-in ends at the job's start and the job runs from complete geometry: its
    setpoints depend on its geometry alone. Returns the job's batches and the publisher."""
    job, n = segments[0].job, len(segments)
    first, second = lead_in(f"lead-{tag}", here, segments[0].points[0], segments[0].axes)
    h.send(first)
    h.wait_event("starved", first.job, timeout=timeout)
    pub = PublisherThread(h.cfg, segments, timeout=timeout, **publish)

    def complete() -> bool:
        st = status(h)
        return st.receiving == job and st.next_seq == n

    deadline = time.monotonic() + timeout
    while not complete():
        assert time.monotonic() < deadline, f"job {job} was not completely received"
        assert pub.thread.is_alive(), f"the publisher ended early: {pub.messages}"
        time.sleep(0.02)
    h.send(second)
    assert pub.join(timeout) == 0, pub.messages
    return h.wait_final(job, timeout=timeout), pub
