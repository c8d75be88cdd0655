"""`lookahead config check FILE` and `lookahead config show`."""

from __future__ import annotations

import argparse
import sys

from lookahead.config import ConfigError, config_to_toml, default_config, load_config


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=help_text)
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    check = verbs.add_parser("check", help="print the resolved configuration, or its errors "
                             "(exit 2)")
    check.add_argument("file", help="machine configuration TOML")
    verbs.add_parser("show", help="print the defaults as TOML that can be saved and edited")
    return p


def run(args: argparse.Namespace) -> int:
    if args.verb == "show":
        print(config_to_toml(default_config()), end="")
        return 0
    try:
        cfg = load_config(args.file)
    except ConfigError as exc:
        for line in exc.errors:
            print(f"config error: {line}", file=sys.stderr)
        return 2
    print(f"# {args.file}: OK (namespace {cfg.ns})")
    print(config_to_toml(cfg), end="")
    return 0
