"""`lookahead monitor`: watch machines on the bus in a web browser (http://127.0.0.1:8470/).

Subscribes to NS/status, events, setpoints, segments, machine/report and the liveliness
tokens of every machine named by `--machine-id` (repeatable or a comma list; default the
configuration's id), and serves a page showing each one live: state, job, progress along
the programmed path, override, planner, fallbacks, events, a scrolling chart of the feed
and of every axis' |v|, |a|, |j| as a fraction of its limit (finite differences of the
commanded positions, computed and decimated here), the path in axis space with the
machine's point on it, the winder's end-of-job report, and hold / resume / abort / override
controls sent as PROTOCOL.md commands. It only subscribes: the service does not wait for it
and a closed browser tab costs the service nothing.

The first line on stdout is the page's address. Ctrl-C stops it.
"""

from __future__ import annotations

import argparse
import os
import sys

DEFAULT_PORT = 8470


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", action="append", default=[], metavar="MACHINE",
                   help="machine configuration (TOML or shipped machine): once for all "
                        "machine ids, or once per --machine-id in the same order")
    p.add_argument("--host", default="127.0.0.1",
                   help="address the page is served on (default 127.0.0.1: this computer only)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"HTTP port (default {DEFAULT_PORT}, a free one if that is busy; 0: "
                        "any free port)")
    p.add_argument("--log-level", default="WARNING", help="logging level (default WARNING)")
    return p


def machine_ids(args: argparse.Namespace, default: str) -> list[str]:
    """The ids of `--machine-id` (repeatable, comma lists), else LOOKAHEAD_MACHINE_ID's,
    else `default`; in order, without repeats."""
    raw = args.machine_id if isinstance(getattr(args, "machine_id", None), list) else \
        [args.machine_id] if getattr(args, "machine_id", None) else \
        [os.environ.get("LOOKAHEAD_MACHINE_ID") or default]
    ids = [part.strip() for item in raw for part in item.split(",") if part.strip()]
    return list(dict.fromkeys(ids))


def build_views(args: argparse.Namespace) -> tuple[dict, object]:
    """(machine id -> MachineView, the zenoh section of the first configuration)."""
    from dataclasses import replace

    from lookahead.config import ConfigError, load_config
    from lookahead_clients.monitor.machine_view import MachineSpec, MachineView

    environ = {k: v for k, v in os.environ.items() if k != "LOOKAHEAD_MACHINE_ID"}
    try:
        base = [load_config(c, environ) for c in (args.config or [None])]
    except ConfigError as exc:
        raise SystemExit(f"monitor: {exc}") from None
    ids = machine_ids(args, base[0].machine.id)
    if len(base) not in (1, len(ids)):
        raise SystemExit(f"monitor: {len(base)} --config for {len(ids)} machine ids: give "
                         "one for all or one per id")
    views = {}
    for i, mid in enumerate(ids):
        cfg = base[i if len(base) > 1 else 0]
        cfg = replace(cfg, machine=replace(cfg.machine, id=mid))
        m = cfg.machine
        spec = MachineSpec(mid, cfg.ns, tuple(m.axes), tuple(m.units), tuple(m.vmax),
                           tuple(m.amax), tuple(m.jmax), tuple(m.path_scale), m.dt)
        views[mid] = MachineView(spec)
    return views, base[0].zenoh


def serve(host: str, port: int, views: dict, bus):
    """A MonitorServer on (host, port); the default port falls back to a free one."""
    from lookahead_clients.monitor.server import MonitorServer

    try:
        return MonitorServer((host, port), views, bus)
    except OSError:
        if port != DEFAULT_PORT:
            raise
        return MonitorServer((host, 0), views, bus)


def run(args: argparse.Namespace) -> int:
    import logging
    import signal

    from lookahead.bus import open_client_session
    from lookahead_clients.monitor.bus_side import MonitorBus

    logging.basicConfig(level=args.log_level.upper(), format="%(name)s: %(message)s")
    views, zenoh_section = build_views(args)
    session = open_client_session(zenoh_section)
    bus = MonitorBus(session, views)
    try:
        server = serve(args.host, args.port, views, bus)
    except OSError as exc:
        bus.close()
        print(f"monitor: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 1

    def _stop(*_args) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _stop)
    print(f"monitor: {server.url} watching {', '.join(v.spec.ns for v in views.values())}",
          flush=True)
    try:
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        pass
    finally:
        server.stopping.set()
        server.server_close()
        bus.close()
    return 0
