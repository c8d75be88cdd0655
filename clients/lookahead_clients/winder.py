"""`lookahead winder`: the simulated two-drive filament winder on the bus.

Subscribes to `NS/setpoints`, runs every job's batches through `JobMonitor` (limit check by
the independent checker, sequence gaps, underruns in real time, servo following error,
fibre angle per traverse), and at the end of each job (its `final` batch, or a fault)
publishes `NS/machine/report` (one MessagePack map, `JobMonitor.report()`) and prints a
summary. Holds the liveliness token `NS/alive/machine`; if `NS/alive/planner` goes away
while a job runs, the job ends with a fault. Exit status: 0 if every job was clean.
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import threading
import time
from collections.abc import Callable

#: how long batches still in flight are awaited after the planner's token went away (s)
PLANNER_GRACE_S = 0.5


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", help="machine configuration TOML (default: built-in)")
    p.add_argument("--fast", action="store_true",
                   help="no real-time clock: consume batches as they come (no underrun check)")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="exit after N jobs (default: run until interrupted)")
    p.add_argument("--exit-after-job", action="store_true", help="same as --jobs 1")
    p.add_argument("--plot", metavar="FILE.png", help="plot each finished job to this file")
    p.add_argument("--report-json", metavar="FILE",
                   help="also write the job reports (a JSON list) to this file")
    p.add_argument("--buffer-s", type=float, default=None,
                   help="real time: the drives start sample 0 this long after the first "
                   "batch arrives (default: the service's lead, service.lead_s)")
    p.add_argument("--quiet", action="store_true", help="no summary on stdout")
    return p


def run(args: argparse.Namespace) -> int:
    from lookahead.config import load_config_or_exit

    cfg = load_config_or_exit(args.config)
    max_jobs = 1 if args.exit_after_job else args.jobs
    reports: list[dict] = []

    def on_report(report: dict, monitor) -> None:
        reports.append(report)
        if not args.quiet:
            from lookahead_clients.machine_job import summary

            print(summary(report), flush=True)
        if args.plot:
            from lookahead_clients.winder_plot import plot_job

            plot_job(args.plot, monitor.arrays(), report, cfg.machine.dt)
            if not args.quiet:
                print(f"  plot: {args.plot}", flush=True)
        if args.report_json:
            with open(args.report_json, "w", encoding="utf-8") as fh:
                json.dump(reports, fh, indent=1)

    buffer_s = cfg.service.lead_s if args.buffer_s is None else args.buffer_s
    run_winder(cfg, realtime=not args.fast, max_jobs=max_jobs, buffer_s=buffer_s,
               on_report=on_report)
    return 0 if all(r["clean"] for r in reports) else 1


def run_winder(cfg, realtime: bool, max_jobs: int | None = None, buffer_s: float = 0.0,
               on_report: Callable[[dict, object], None] | None = None,
               stop: threading.Event | None = None, ready: threading.Event | None = None
               ) -> list[dict]:
    """The winder's bus loop; returns the job reports. Ends after `max_jobs` jobs or when
    `stop` is set. `ready` is set once the subscriptions and the token are declared."""
    import msgpack

    from lookahead.bus import open_client_session
    from lookahead.protocol import ProtocolError, SetpointBatch, key
    from lookahead_clients.busio import close_session, publisher, subscribe, watch_liveliness
    from lookahead_clients.machine_job import JobMonitor, MachineModel

    machine = MachineModel(tuple(cfg.machine.axes), cfg.machine.limits,
                           tuple(cfg.machine.path_scale), cfg.machine.dt)
    stop = stop or threading.Event()
    reports: list[dict] = []
    inbox: queue.Queue = queue.Queue()
    session = open_client_session(cfg.zenoh)
    try:
        subscribe(session, key(cfg.ns, "setpoints"), inbox)
        events: queue.Queue = queue.Queue()
        subscribe(session, key(cfg.ns, "events"), events)
        fallbacks: dict[str, int] = {}  # job -> `fallbacks` of its job_finished event
        watch_liveliness(session, key(cfg.ns, "alive", "planner"), inbox)
        report_pub = publisher(session, key(cfg.ns, "machine", "report"))
        token = session.liveliness().declare_token(key(cfg.ns, "alive", "machine"))
        if ready is not None:
            ready.set()
        current: JobMonitor | None = None
        finished: set[str] = set()

        def finish(monitor: JobMonitor) -> None:
            monitor.fallbacks = job_fallbacks(events, fallbacks, monitor.job)
            report = monitor.report()
            finished.add(monitor.job)
            report_pub.put(msgpack.packb(report, use_bin_type=True))
            reports.append(report)
            if on_report is not None:
                on_report(report, monitor)

        planner_gone_at: float | None = None
        while not stop.is_set() and (max_jobs is None or len(reports) < max_jobs):
            try:
                item = inbox.get(timeout=0.05)
            except queue.Empty:
                # batches in flight may arrive after the planner's token went away: the job
                # is given up once nothing more has come for PLANNER_GRACE_S
                if planner_gone_at is not None and current is not None and \
                        time.monotonic() - max(planner_gone_at, current.last_arrival) \
                        > PLANNER_GRACE_S:
                    current.fault = current.fault or "the planner's liveliness token went " \
                        "away in the middle of the job"
                    finish(current)
                    current = None
                continue
            if item.kind in ("alive", "gone"):
                planner_gone_at = item.t if item.kind == "gone" else None
                continue
            if item.kind != "put":
                continue
            try:
                batch = SetpointBatch.decode(item.payload)
            except ProtocolError as exc:
                print(f"winder: bad setpoint batch ignored: {exc}", file=sys.stderr)
                if current is not None:
                    current.gaps += 1
                continue
            if batch.job in finished:
                continue  # late batches of a job already reported
            if current is not None and batch.job != current.job:
                current.fault = current.fault or f"job {batch.job} started before this one " \
                    "ended"
                finish(current)
                current = None
            if current is None:
                current = JobMonitor(machine, batch.job, realtime, buffer_s)
            current.add(batch, item.t)
            if current.final:
                finish(current)
                current = None
        token.undeclare()
    finally:
        close_session(session)
    return reports


#: how long a finished job's report waits for the service's job_finished event (s)
EVENT_GRACE_S = 1.0


def job_fallbacks(events: queue.Queue, seen: dict[str, int], job: str) -> int | None:
    """The `fallbacks` of `job`'s job_finished event (window plans the configured planner
    could not make), read from the events queue for up to EVENT_GRACE_S; None if it did
    not come (or came from a service without the field)."""
    from lookahead.protocol import Event, ProtocolError

    deadline = time.monotonic() + EVENT_GRACE_S
    while job not in seen:
        try:
            item = events.get(timeout=max(deadline - time.monotonic(), 0.0))
        except queue.Empty:
            return None
        if item.kind != "put":
            continue
        try:
            event = Event.decode(item.payload)
        except ProtocolError:
            continue
        if event.type == "job_finished" and event.job is not None:
            value = event.extra.get("fallbacks")
            seen[event.job] = int(value) if isinstance(value, int) else -1
    value = seen.pop(job)
    return None if value < 0 else value
