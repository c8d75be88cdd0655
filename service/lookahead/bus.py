"""Zenoh sessions for the service and the clients, built from the `[zenoh]` config section.

Only this module and the clients import zenoh. Defaults: the service is a peer listening on
tcp/127.0.0.1:7447 with multicast scouting off; a client of the default configuration
connects to the service's listen endpoints instead of listening itself.
"""

from __future__ import annotations

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


def reliable_publisher(session, key_expr: str):
    """A publisher that does not lose messages (PROTOCOL.md "Delivery"): reliable, and
    blocking instead of dropping when the transmission queue is full (zenoh's default
    congestion control drops under load, even on loopback)."""
    import zenoh

    return session.declare_publisher(key_expr,
                                     congestion_control=zenoh.CongestionControl.BLOCK,
                                     reliability=zenoh.Reliability.RELIABLE)


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
