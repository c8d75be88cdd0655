"""`lookahead serve --config FILE [--fast] [--log-level LEVEL]`: the planner service."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=help_text)
    p.add_argument("--config", metavar="FILE", default=None,
                   help="machine configuration TOML (default: the built-in winder)")
    p.add_argument("--fast", action="store_true",
                   help="publish setpoints as fast as possible instead of in real time "
                   "(tests, replay)")
    p.add_argument("--method", choices=("heuristic", "lp"), default=None,
                   help="planner method (default: planner.method of the configuration)")
    p.add_argument("--log-level", default="INFO",
                   choices=("DEBUG", "INFO", "WARNING", "ERROR"), help="log level (INFO)")
    return p


def run(args: argparse.Namespace) -> int:
    import dataclasses
    import logging
    import signal
    import sys

    from lookahead.config import load_config_or_exit

    logging.basicConfig(level=getattr(logging, args.log_level), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    cfg = load_config_or_exit(args.config)
    if args.method:
        cfg = dataclasses.replace(cfg, planner=dataclasses.replace(cfg.planner,
                                                                   method=args.method))
    from lookahead.service import PlannerService

    service = PlannerService(cfg, fast=args.fast)

    def on_signal(signum: int, _frame: object) -> None:
        logging.getLogger("lookahead.service").info("signal %d: finishing the stop", signum)
        service.request_shutdown()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        service.open()
    except Exception as exc:
        logging.getLogger("lookahead.service").error("cannot open the zenoh session: %s", exc)
        return 1
    try:
        return service.run()
    finally:
        service.close()
