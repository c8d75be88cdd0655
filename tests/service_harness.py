"""Test harness: a PlannerService in a thread on a random loopback port, and a client
session that publishes segments, sends commands and collects setpoints and events."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np

from lookahead.bus import free_tcp_endpoint, open_client_session, with_endpoints
from lookahead.checker import LimitChecker
from lookahead.config import Config, default_config
from lookahead.protocol import Command, CommandReply, Event, Segment, SetpointBatch, key
from lookahead.service import PlannerService

CONNECT_S = 0.6


def service_config(method: str = "heuristic", **service: float) -> Config:
    cfg = default_config()
    return replace(cfg, zenoh=with_endpoints(cfg.zenoh, listen=[free_tcp_endpoint()]),
                   planner=replace(cfg.planner, method=method),
                   service=replace(cfg.service, **service))


def point_segments(job: str, points: np.ndarray, sizes: list[int], axes=("X", "C"),
                   fit: str = "cubic", last: bool = True) -> list[Segment]:
    """Consecutive chunks of `points` of the given sizes (the last takes the rest)."""
    cuts = np.cumsum(sizes)
    chunks = [c for c in np.split(points, cuts[cuts < len(points)]) if len(c)]
    return [Segment(job, i, tuple(axes), "points", last and i == len(chunks) - 1,
                    points=c, fit=fit) for i, c in enumerate(chunks)]


def random_sizes(rng: np.random.Generator, n: int, lo: int = 1, hi: int = 400) -> list[int]:
    sizes = []
    while sum(sizes) < n:
        sizes.append(int(rng.integers(lo, hi)))
    return sizes


class Harness:
    """A running service and a client connected to it."""

    def __init__(self, cfg: Config, fast: bool = True) -> None:
        import zenoh

        self.cfg = cfg
        self.ns = cfg.ns
        self.service = PlannerService(cfg, fast=fast)
        self.service.open()
        self.thread = threading.Thread(target=self.service.run, daemon=True)
        self.thread.start()
        self.client = open_client_session(cfg.zenoh)
        self.lock = threading.Lock()
        self.batches: list[SetpointBatch] = []
        self.events: list[Event] = []
        self._subs = [
            self.client.declare_subscriber(key(self.ns, "setpoints"), self._on_batch),
            self.client.declare_subscriber(key(self.ns, "events"), self._on_event),
        ]
        self.pub = self.client.declare_publisher(
            key(self.ns, "segments"), congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(CONNECT_S)

    def _on_batch(self, sample) -> None:
        batch = SetpointBatch.decode(sample.payload.to_bytes())
        with self.lock:
            self.batches.append(batch)

    def _on_event(self, sample) -> None:
        event = Event.decode(sample.payload.to_bytes())
        with self.lock:
            self.events.append(event)

    # --- actions --------------------------------------------------------------------
    def send(self, seg: Segment | bytes) -> None:
        self.pub.put(seg if isinstance(seg, bytes) else seg.encode())

    def command(self, verb: str, value: float | None = None) -> CommandReply:
        cmd = Command(verb, value)
        replies = list(self.client.get(key(self.ns, "cmd", verb), payload=cmd.encode(),
                                       timeout=10.0))
        assert replies, f"no reply to {verb}"
        return CommandReply.decode(replies[0].ok.payload.to_bytes())

    def status_bytes(self) -> bytes:
        replies = list(self.client.get(key(self.ns, "status"), timeout=5.0))
        assert replies, "no status reply"
        return replies[0].ok.payload.to_bytes()

    # --- waiting --------------------------------------------------------------------
    def wait_for(self, predicate, timeout: float = 20.0, what: str = "condition") -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                if predicate():
                    return
            time.sleep(0.01)
        raise AssertionError(f"timed out waiting for {what}")

    def wait_final(self, job: str, timeout: float = 30.0) -> list[SetpointBatch]:
        self.wait_for(lambda: any(b.job == job and b.final for b in self.batches), timeout,
                      f"the final batch of {job}")
        return self.job_batches(job)

    def wait_event(self, etype: str, job: str | None = None, timeout: float = 20.0,
                   count: int = 1) -> list[Event]:
        def found() -> bool:
            return len(self._events_of(etype, job)) >= count

        self.wait_for(found, timeout, f"{count} {etype} event(s)")
        with self.lock:
            return self._events_of(etype, job)

    def _events_of(self, etype: str, job: str | None) -> list[Event]:
        return [e for e in self.events if e.type == etype and (job is None or e.job == job)]

    def job_batches(self, job: str) -> list[SetpointBatch]:
        with self.lock:
            return sorted((b for b in self.batches if b.job == job), key=lambda b: b.seq)

    def close(self) -> None:
        self.service.request_shutdown()
        self.thread.join(timeout=30)
        for sub in self._subs:
            sub.undeclare()
        self.client.close()
        self.service.close()


def check_job(batches: list[SetpointBatch], cfg: Config, start: np.ndarray, end: np.ndarray,
              tol: float = 1e-6):
    """Assert the batches of one job tile 0..K-1, pass the checker across batches, start
    and end at rest at the given points; returns (pos, vel, report)."""
    assert batches, "no batches"
    assert [b.seq for b in batches] == list(range(len(batches)))
    k = 0
    checker = LimitChecker(cfg.machine.limits, cfg.machine.dt)
    for b in batches:
        assert b.k0 == k, f"batch {b.seq} starts at k0={b.k0}, expected {k}"
        k += b.n
        checker.feed(b.pos)
    assert batches[-1].final and not any(b.final for b in batches[:-1])
    pos = np.vstack([b.pos for b in batches])
    vel = np.vstack([b.vel for b in batches])
    acc = np.vstack([b.acc for b in batches])
    report = checker.report()
    assert report.ok, f"limits broken: {report.first} ({report.violations} violations)"
    np.testing.assert_allclose(pos[0], start, atol=tol)
    np.testing.assert_allclose(pos[-1], end, atol=tol)
    for arr in (vel, acc):
        np.testing.assert_allclose(arr[0], 0.0, atol=1e-6)
        np.testing.assert_allclose(arr[-1], 0.0, atol=1e-6)
    return pos, vel, report
