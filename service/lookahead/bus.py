"""Zenoh sessions for the service and the clients, built from the `[zenoh]` config section.

Only this module and the clients import zenoh. Defaults: the service is a peer listening on
tcp/127.0.0.1:7447 with multicast scouting off; a client of the default configuration
connects to the service's listen endpoints instead of listening itself.
"""

from __future__ import annotations

import datetime
import json
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

from lookahead.config import ZenohSection

#: zenoh's lease: how soon a hung peer is declared gone (DESIGN.md, "Zenoh")
_LEASE_MS = 1000


def zenoh_config(section: ZenohSection):
    """A zenoh.Config for `section` (the JSON5 file first, then our keys on top)."""
    import zenoh

    conf = zenoh.Config.from_file(section.config_file) if section.config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(section.mode))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(section.multicast_scouting))
    conf.insert_json5("listen/endpoints", json.dumps(list(section.listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(section.connect)))
    conf.insert_json5("transport/link/tx/lease", str(_LEASE_MS))
    return conf


def init_zenoh_logging() -> None:
    """zenoh's own log (transport closes, lease expiries) on stderr when RUST_LOG is set
    (e.g. RUST_LOG=zenoh=warn); nothing otherwise. Safe to call more than once."""
    import zenoh

    zenoh.try_init_log_from_env()


def open_session(section: ZenohSection):
    """Open a zenoh session for the service (as configured)."""
    import zenoh

    init_zenoh_logging()
    return zenoh.open(zenoh_config(section))


#: messages an advanced publisher keeps for subscribers that missed some (`reliable_publisher`)
RECOVERY_CACHE = 10_000
#: the setpoints' cache: a batch of 10 samples of 3 axes is ~350 B, so ~18 MB; 500 s of
#: motion in real time, 25 s of a paused receiver at 20x real time (`serve --fast`)
SETPOINT_CACHE = 50_000
#: the publisher's heartbeat period (s): zenoh retransmits only from publishers with miss
#: detection on, and a periodic heartbeat (unlike the "sporadic" one, sent only on change)
#: keeps announcing a stream's last sequence number after the stream ends
HEARTBEAT_S = 0.25
#: how often a `recovering_subscriber` asks the publishers it knows for what it has not
#: received (s). Periodic queries, not zenoh's heartbeat recovery: a subscriber listening to
#: heartbeats fetched a publisher's whole cache when it joined (old jobs' batches), and
#: queries also recover the tail of a stream (a receiver paused 5 s past its end)
RECOVERY_QUERY_S = 0.5


def reliable_publisher(session, key_expr: str, cache: int = RECOVERY_CACHE):
    """A publisher that does not lose messages (PROTOCOL.md "Delivery"): reliable, and
    blocking instead of dropping when the transmission queue is full (zenoh's default
    congestion control drops under load, even on loopback).

    It is zenoh's advanced publisher with a cache of the last `cache` messages and sequence
    numbers: a receiver stalled longer than the lease (`_LEASE_MS`, e.g. starved of CPU or
    paused) has its transport closed, and every message put meanwhile was lost silently
    (seen twice on a loaded machine, README "Stop 32"); a `recovering_subscriber` fetches
    them from the cache once it is back, in order. A plain subscriber (PROTOCOL.md alone)
    receives the same messages without the recovery."""
    import zenoh
    from zenoh import ext

    return ext.declare_advanced_publisher(
        session, key_expr,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
        cache=ext.CacheConfig(max_samples=cache),
        sample_miss_detection=ext.MissDetectionConfig(heartbeat=HEARTBEAT_S))


def recovering_subscriber(session, key_expr: str, capacity: int,
                          on_miss: Callable[[int], None] | None = None):
    """A FifoChannel subscriber of `capacity` samples that recovers what it missed from a
    `reliable_publisher` (from its cache, delivered in order; from a plain publisher it
    receives like a plain subscriber). `on_miss(n)`: n messages were lost for good (they
    had left the publisher's cache)."""
    import zenoh
    from zenoh import ext

    period = datetime.timedelta(seconds=RECOVERY_QUERY_S)
    sub = ext.declare_advanced_subscriber(session, key_expr,
                                          zenoh.handlers.FifoChannel(capacity),
                                          recovery=ext.RecoveryConfig(periodic_queries=period))
    if on_miss is not None:
        listener = sub.sample_miss_listener(lambda miss: on_miss(int(miss.nb)))
        _miss_listeners[id(sub)] = listener  # undeclared when dropped: keep it
    return sub


#: the miss listeners of `recovering_subscriber`, by the id of their subscriber
_miss_listeners: dict[int, object] = {}


def client_section(section: ZenohSection) -> ZenohSection:
    """The session a client opens against a service configured with `section`.

    A peer service that only listens is reached by connecting to its listen endpoints; a
    configuration that names connect endpoints (a router) is used as it is.

    A peer does not route between other peers, so a peer client also listens on an
    ephemeral port of the service's host: gossip then connects the clients to each other
    (the recorder sees the publisher's segments, the demo sees the winder's token)."""
    if section.connect or section.mode == "client":
        return replace(section, listen=())
    listen = tuple(ep for ep in map(_ephemeral, section.listen[:1]) if ep)
    return replace(section, listen=listen, connect=section.listen)


def _ephemeral(endpoint: str) -> str | None:
    """`tcp/HOST:PORT` -> `tcp/HOST:0` (a free port on the same host), None if not tcp."""
    proto, _, addr = endpoint.partition("/")
    if proto != "tcp" or ":" not in addr:
        return None
    return f"tcp/{addr.split('#')[0].rsplit(':', 1)[0]}:0"


def open_client_session(section: ZenohSection):
    """Open a zenoh session for a client (publisher, winder, recorder, monitor)."""
    import zenoh

    init_zenoh_logging()
    return zenoh.open(zenoh_config(client_section(section)))


def free_tcp_endpoint(host: str = "127.0.0.1") -> str:
    """A tcp endpoint on a currently free port of `host` (for tests and the demo)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return f"tcp/{host}:{sock.getsockname()[1]}"


def with_endpoints(section: ZenohSection, listen: Sequence[str] | None = None,
                   connect: Sequence[str] | None = None) -> ZenohSection:
    """`section` with listen/connect endpoints replaced where given."""
    out = section
    if listen is not None:
        out = replace(out, listen=tuple(listen))
    if connect is not None:
        out = replace(out, connect=tuple(connect))
    return out


#: how long a drain loop sleeps when its channel is empty (s)
POLL_IDLE_S = 0.002


def poll_fifo(sub, handle: Callable[[object], None], stop: threading.Event,
              idle_s: float = POLL_IDLE_S) -> None:
    """Hand every sample of a FifoChannel subscriber to `handle` until `stop` is set.

    Polls `try_recv` rather than blocking in `recv`: a thread blocked in `recv` cannot be
    interrupted, and zenoh aborts the process if its session closes under it."""
    while not stop.is_set():
        sample = sub.try_recv()
        if sample is None:
            time.sleep(idle_s)
            continue
        handle(sample)
