"""`lookahead status`: ask the service for its status once (also the container healthcheck).

Exit 0 with the status printed; 1 if no planner answers (or, with `--expect`, if that
liveliness token is absent) within the timeout.
"""

from __future__ import annotations

import argparse
import sys
import time


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__)
    p.add_argument("--config", help="machine configuration TOML (default: built-in)")
    p.add_argument("--expect", choices=("planner", "machine"), action="append", default=[],
                   help="also require this liveliness token (repeatable)")
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait (default 3)")
    return p


def run(args: argparse.Namespace) -> int:
    from lookahead.bus import open_client_session
    from lookahead.config import load_config_or_exit
    from lookahead.protocol import ProtocolError, Status, key
    from lookahead_clients.busio import query_once

    cfg = load_config_or_exit(args.config)
    session = open_client_session(cfg.zenoh)
    try:
        deadline = time.monotonic() + args.timeout
        status = None
        while status is None and time.monotonic() < deadline:
            raw = query_once(session, key(cfg.ns, "status"), max(0.1, args.timeout))
            if raw is None:
                time.sleep(0.2)
                continue
            try:
                status = Status.decode(raw)
            except ProtocolError as exc:
                print(f"status: malformed reply: {exc}", file=sys.stderr)
                return 1
        missing = [who for who in args.expect
                   if not _alive(session, key(cfg.ns, "alive", who), deadline)]
        if status is None:
            print(f"status: no planner answered on {key(cfg.ns, 'status')} within "
                  f"{args.timeout} s", file=sys.stderr)
            return 1
        print(describe(cfg.ns, status))
        if missing:
            print(f"status: no liveliness token for {', '.join(missing)}", file=sys.stderr)
            return 1
        return 0
    finally:
        session.close()


def describe(ns: str, status) -> str:
    """The line printed for a `lookahead.protocol.Status`: its fields as name=value; times in
    s, `remaining_s` None while the plan does not reach the job's end."""
    remaining = "None" if status.remaining_s is None else f"{status.remaining_s:.3f}"
    return (f"{ns}: state={status.state} job={status.job} k={status.k} "
            f"queued={status.queued} horizon_s={status.horizon_s:.3f} "
            f"override={status.override} planner={status.planner} "
            f"plan_ms={status.plan_ms:.2f} error={status.error} "
            f"plan_complete={status.plan_complete} remaining_s={remaining}")


def _alive(session, token_key: str, deadline: float) -> bool:
    """True if a liveliness token `token_key` is present."""
    timeout = max(0.1, deadline - time.monotonic())
    return any(reply.ok is not None for reply in session.liveliness().get(token_key,
                                                                           timeout=timeout))
