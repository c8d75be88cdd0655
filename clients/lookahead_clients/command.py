"""`lookahead cmd VERB [VALUE]`: send one command to the planner service and print its reply.

Verbs (PROTOCOL.md "Commands"): `hold` (decelerate along the path to rest and hold),
`resume`, `override F` (scale the path speed, 0 < F <= 1.5), `abort` (stop along the path
and end the job), `reset` (clear a fault). Exit 0 if the service accepted it, 1 if it
refused (its reason on stderr), 2 on a bad verb or value, 4 if no service answered.
"""

from __future__ import annotations

import argparse
import sys

from lookahead.protocol import COMMANDS


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("verb", choices=COMMANDS, help="the command")
    p.add_argument("value", nargs="?", type=float,
                   help="override: the path-speed factor (0 < F <= 1.5)")
    p.add_argument("--config", help="machine configuration TOML (default: built-in)")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait (default 5)")
    return p


def run(args: argparse.Namespace) -> int:
    from lookahead.bus import open_client_session
    from lookahead.config import load_config_or_exit
    from lookahead.protocol import Command, CommandReply, ProtocolError, key
    from lookahead_clients.busio import query_once

    if (args.verb == "override") != (args.value is not None):
        print("cmd: override takes a value (e.g. `lookahead cmd override 0.5`), the other "
              "verbs none", file=sys.stderr)
        return 2
    payload = Command(args.verb, args.value).encode()
    try:  # the service's own validation, so a bad value is refused before sending
        cmd = Command.decode(args.verb, payload)
    except ProtocolError as exc:
        print(f"cmd: {exc}", file=sys.stderr)
        return 2
    cfg = load_config_or_exit(args.config)
    target = key(cfg.ns, "cmd", cmd.verb)
    session = open_client_session(cfg.zenoh)
    try:
        raw = query_once(session, target, args.timeout, payload)
    finally:
        session.close()
    if raw is None:
        print(f"cmd: no planner answered on {target} within {args.timeout} s",
              file=sys.stderr)
        return 4
    try:
        answer = CommandReply.decode(raw)
    except ProtocolError as exc:
        print(f"cmd: malformed reply: {exc}", file=sys.stderr)
        return 1
    if not answer.ok:
        print(f"cmd: {cmd.verb} refused: {answer.error}", file=sys.stderr)
        return 1
    print(f"{cfg.ns}: {cmd.verb}{'' if cmd.value is None else f' {cmd.value:g}'} accepted")
    return 0
