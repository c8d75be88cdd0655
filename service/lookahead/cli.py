"""The `lookahead` command line: one console script, one subcommand per job.

Each subcommand lives in its own module exposing `add_parser(subparsers)` (cheap: no heavy
imports at module level) and `run(args) -> int`. A subcommand whose module is not part of
this build says so and exits 3 instead of pretending.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from lookahead import __version__

#: subcommand -> (module, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "config": ("lookahead.config_cli", "check or show the machine configuration"),
    "plan": ("lookahead.plan_cli", "plan a whole job offline and report/plot it"),
    "serve": ("lookahead.serve_cli", "run the planner service on the Zenoh bus"),
    "publish": ("lookahead_clients.publisher", "publish a job's segments on the bus"),
    "winder": ("lookahead_clients.winder", "run the simulated two-drive filament winder"),
    "record": ("lookahead_clients.recorder", "record everything under NS/** to a file"),
    "replay": ("lookahead_clients.replay", "replay a recording into a fresh service"),
    "demo": ("lookahead_clients.demo", "service + winder + publisher together (tube-1450)"),
    "status": ("lookahead_clients.status", "ask the service for its status (healthcheck)"),
    "cmd": ("lookahead_clients.command", "hold, resume, override, abort or reset the service"),
    "monitor": ("lookahead_clients.monitor.cli", "watch machines live in a web browser"),
}

EXIT_NOT_BUILT = 3

#: bus options every subcommand takes -> the configuration's environment override
BUS_OPTIONS: dict[str, str] = {
    "machine_id": "LOOKAHEAD_MACHINE_ID",
    "zenoh_mode": "LOOKAHEAD_ZENOH_MODE",
    "connect": "LOOKAHEAD_ZENOH_CONNECT",
    "listen": "LOOKAHEAD_ZENOH_LISTEN",
    "zenoh_config": "LOOKAHEAD_ZENOH_CONFIG_FILE",
}


def _add_bus_options(parser: argparse.ArgumentParser, many_ids: bool = False) -> None:
    group = parser.add_argument_group(
        "bus", "override the configuration's machine id and zenoh session (the same as the "
        "LOOKAHEAD_MACHINE_ID / LOOKAHEAD_ZENOH_* environment variables)")
    if many_ids:  # the monitor watches several machines
        group.add_argument("--machine-id", metavar="ID", action="append",
                           help="namespace lookahead/ID (repeatable, or a comma list)")
    else:
        group.add_argument("--machine-id", metavar="ID", help="namespace lookahead/ID")
    group.add_argument("--zenoh-mode", choices=("peer", "client", "router"))
    group.add_argument("--connect", metavar="ENDPOINT", action="append",
                       help="connect to ENDPOINT, e.g. tcp/router:7447 (repeatable)")
    group.add_argument("--listen", metavar="ENDPOINT", action="append",
                       help="listen on ENDPOINT (repeatable; '' for none)")
    group.add_argument("--zenoh-config", metavar="FILE",
                       help="zenoh JSON5 config file (TLS, credentials, access control)")


def _export_bus_options(args: argparse.Namespace) -> None:
    """Bus options become environment overrides, read by `load_config` here and inherited
    by the subprocesses a command starts (the demo)."""
    for attr, var in BUS_OPTIONS.items():
        value = getattr(args, attr, None)
        if value is not None:
            os.environ[var] = ",".join(value) if isinstance(value, list) else value


def _not_built(name: str, module: str, reason: str):
    def run(_args: argparse.Namespace) -> int:
        print(f"lookahead {name}: not available in this build ({module}: {reason}).",
              file=sys.stderr)
        return EXIT_NOT_BUILT

    return run


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lookahead",
        description="Jerk-limited look-ahead feedrate planner and interpolator on Zenoh.",
    )
    parser.add_argument("--version", action="version", version=f"lookahead {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name is None or not module_name.startswith(exc.name):
                raise  # a real missing dependency, not an unbuilt subcommand
            stub = sub.add_parser(name, help=f"{help_text} [not built]")
            stub.add_argument("rest", nargs=argparse.REMAINDER)
            stub.set_defaults(func=_not_built(name, module_name, "module missing"))
            continue
        p = module.add_parser(sub, name, help_text)
        if name != "plan":  # plans offline, never touches the bus
            _add_bus_options(p, many_ids=name == "monitor")
        p.set_defaults(func=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    _export_bus_options(args)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
