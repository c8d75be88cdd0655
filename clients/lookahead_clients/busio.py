"""Small zenoh helpers shared by the clients (imported inside `run()`: imports zenoh).

Incoming samples are drained from a FifoChannel by a daemon thread into a `queue.Queue` as
`Arrival(kind, t, key, payload)` items stamped with `time.monotonic()` on receipt; the
thread ends when the session closes. Liveliness changes arrive on the same queue (kind
"alive" or "gone"), so their order relative to data is kept.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import NamedTuple

import zenoh

from lookahead.bus import poll_fifo, recovering_subscriber, reliable_publisher

log = logging.getLogger(__name__)

FIFO_CAPACITY = 8192


class Arrival(NamedTuple):
    """One received sample: kind 'put' | 'delete' | 'alive' | 'gone', monotonic time (s)."""

    kind: str
    t: float
    key: str
    payload: bytes


def _kind(sample: zenoh.Sample, liveliness: bool) -> str:
    put = sample.kind == zenoh.SampleKind.PUT
    if liveliness:
        return "alive" if put else "gone"
    return "put" if put else "delete"


#: drain threads by the id of the session they read from
_drains: dict[int, list[tuple[threading.Event, threading.Thread]]] = {}


def drain(sub, out: queue.Queue, liveliness: bool = False, session=None) -> threading.Thread:
    """Start a daemon thread moving the samples of a FifoChannel subscriber to `out`.

    It polls `try_recv` instead of blocking in `recv`: a thread blocked in `recv` while the
    session closes makes zenoh abort the process. `close_session(session)` stops the threads
    registered for that session first."""
    stop = threading.Event()

    def put(sample: zenoh.Sample) -> None:
        out.put(Arrival(_kind(sample, liveliness), time.monotonic(), str(sample.key_expr),
                        sample.payload.to_bytes()))

    def loop() -> None:
        try:
            poll_fifo(sub, put, stop)
        except zenoh.ZError:
            return  # the session closed

    thread = threading.Thread(target=loop, daemon=True, name=f"drain-{id(sub)}")
    _drains.setdefault(id(session), []).append((stop, thread))
    thread.start()
    return thread


def close_session(session) -> None:
    """Stop the drain threads reading from `session`, then close it."""
    for stop, thread in _drains.pop(id(session), []):
        stop.set()
        thread.join(timeout=1.0)
    session.close()


def subscribe(session, key_expr: str, out: queue.Queue):
    """Subscribe `key_expr` into `out` (see module docstring); returns the subscriber.

    What a stall of this process made it miss from the service's publishers is recovered
    from their caches (`lookahead.bus.recovering_subscriber`); what had left the cache is
    logged at WARNING (the winder then also sees the gap in the batches' seq)."""
    def lost(n: int) -> None:
        log.warning("%s: %d messages lost for good (no longer in the publisher's cache)",
                    key_expr, n)

    sub = recovering_subscriber(session, key_expr, FIFO_CAPACITY, on_miss=lost)
    drain(sub, out, session=session)
    return sub


def watch_liveliness(session, key_expr: str, out: queue.Queue):
    """Liveliness tokens matching `key_expr` (current ones too) into `out` as alive/gone."""
    sub = session.liveliness().declare_subscriber(
        key_expr, zenoh.handlers.FifoChannel(256), history=True)
    drain(sub, out, liveliness=True, session=session)
    return sub


def publisher(session, key_expr: str):
    """A reliable publisher that blocks instead of dropping under congestion and keeps a
    cache for subscribers that missed messages (`lookahead.bus.reliable_publisher`)."""
    return reliable_publisher(session, key_expr)


def wait_for_token(session, key_expr: str, timeout: float) -> bool:
    """True once a liveliness token matching `key_expr` exists (waits up to `timeout` s)."""
    deadline = time.monotonic() + timeout
    while True:
        replies = session.liveliness().get(key_expr, timeout=0.5)
        if any(r.ok is not None for r in replies):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.1)


def query_once(session, key_expr: str, timeout: float, payload: bytes | None = None
               ) -> bytes | None:
    """The payload of the first successful reply to one `get` on `key_expr` (with
    `payload` if given), or None if none came within `timeout` s."""
    kwargs = {} if payload is None else {"payload": payload}
    for reply in session.get(key_expr, timeout=timeout, **kwargs):
        if reply.ok is not None:
            return reply.ok.payload.to_bytes()
    return None
