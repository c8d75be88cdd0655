"""`lookahead record OUT`: write everything on `NS/**` (and the liveliness tokens under
`NS/alive/**`) to a recording file, with receive times and, for every segment, the sample
index at which the service took it in. The format is described in
`lookahead_clients.recording`. Runs until Ctrl-C / SIGTERM, `--duration`, or `--jobs N`
job_finished events (then `--tail-s` more, to catch the machine's report).
"""

from __future__ import annotations

import argparse
import sys
import threading


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", help="recording file to write")
    p.add_argument("--config", help="machine configuration TOML (default: built-in); use "
                   "the service's, replay plans with it")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="stop after N job_finished events")
    p.add_argument("--duration", type=float, default=None, help="stop after this many s")
    p.add_argument("--tail-s", type=float, default=1.0,
                   help="with --jobs: keep recording this long after the last job (1 s)")
    return p


def run(args: argparse.Namespace) -> int:
    import signal

    from lookahead.config import load_config_or_exit

    cfg = load_config_or_exit(args.config)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        count = record(cfg, args.out, stop, jobs=args.jobs, duration=args.duration,
                       tail_s=args.tail_s)
    except KeyboardInterrupt:
        count = None
    print(f"record: {args.out}" + (f": {count} records" if count is not None else ""),
          file=sys.stderr)
    return 0


def record(cfg, out: str, stop: threading.Event, jobs: int | None = None,
           duration: float | None = None, tail_s: float = 1.0,
           ready: threading.Event | None = None) -> int:
    """Record until `stop`, `duration` seconds or `jobs` finished jobs (+ tail_s); returns
    the number of records written."""
    import queue
    import time

    from lookahead.bus import open_client_session
    from lookahead.config import config_to_toml
    from lookahead.protocol import Event, ProtocolError, SetpointBatch, key
    from lookahead_clients.busio import close_session, subscribe, watch_liveliness
    from lookahead_clients.recording import RecordingWriter

    inbox: queue.Queue = queue.Queue()
    session = open_client_session(cfg.zenoh)
    t0 = time.monotonic()
    end = t0 + duration if duration else float("inf")
    finished_jobs = 0
    seen_applied: set[tuple[str, int]] = set()
    try:
        with open(out, "wb") as fh:
            writer = RecordingWriter(fh, cfg.ns, config_to_toml(cfg), time.time())
            subscribe(session, key(cfg.ns, "**"), inbox)
            watch_liveliness(session, key(cfg.ns, "alive", "**"), inbox)
            if ready is not None:
                ready.set()
            while not stop.is_set() and time.monotonic() < end:
                try:
                    item = inbox.get(timeout=0.05)
                except queue.Empty:
                    continue
                t = item.t - t0
                if item.kind in ("alive", "gone"):
                    writer.liveliness(t, item.key, item.kind == "alive")
                    continue
                writer.sample(t, item.key, item.kind, item.payload)
                if item.kind != "put":
                    continue
                try:
                    if item.key == key(cfg.ns, "setpoints"):
                        batch = SetpointBatch.decode(item.payload)
                        for job, seq in batch.applied:
                            if (job, seq) not in seen_applied:
                                seen_applied.add((job, seq))
                                writer.applied(t, job, seq, batch.k0, batch.job)
                    elif item.key == key(cfg.ns, "events") and jobs is not None and \
                            Event.decode(item.payload).type == "job_finished":
                        finished_jobs += 1
                        if finished_jobs >= jobs:
                            end = min(end, time.monotonic() + tail_s)
                except ProtocolError:
                    pass  # recorded as received; nothing more to learn from it
            return writer.count
    finally:
        close_session(session)
