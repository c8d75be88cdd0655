"""`lookahead publish PRESET|FILE`: send one job's segments to the planner service.

Waits for `NS/alive/planner`, publishes the job as `points` segments of `--chunk` points
(all at once, or `--rate` segments per second), shows the job's progress (segments
executed, from `NS/status`) and waits for the job's end on `NS/events`.
Exit status: 0 on `job_finished`, 1 on `rejected` / `fault` / the planner going away (the
reason on stderr), 2 on a bad source or configuration, 4 on a timeout.
"""

from __future__ import annotations

import argparse
import sys
import time

EXIT_FAILED, EXIT_BAD_INPUT, EXIT_TIMEOUT = 1, 2, 4


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", help="preset (tube-1450, tube-9570), points file (.csv/.npy) "
                   "or G-code file (.gcode/.nc/.ngc)")
    p.add_argument("--config", help="machine configuration TOML (default: built-in)")
    p.add_argument("--job", help="job id (default: <source>-<unix ms>)")
    p.add_argument("--chunk", type=int, default=500, help="points per segment (default 500)")
    p.add_argument("--rate", type=float, default=0.0,
                   help="segments per second (default 0: all at once)")
    p.add_argument("--fit", choices=("cubic", "pchip"), default=None,
                   help="curve through the points (default: the config's planner.fit)")
    p.add_argument("--feed", type=float, default=None, help="path speed cap (units/s)")
    p.add_argument("--circuits", default=None,
                   help="presets: number of circuits or 'layer' (default 1)")
    p.add_argument("--wait-s", type=float, default=10.0,
                   help="how long to wait for the planner to appear (default 10 s)")
    p.add_argument("--timeout", type=float, default=0.0,
                   help="give up after this many seconds in all (default 0: never)")
    p.add_argument("--quiet", action="store_true", help="no progress bar or messages")
    return p


def _circuits(text: str | None) -> int | str | None:
    if text is None or text == "layer":
        return text
    return int(text)


def run(args: argparse.Namespace) -> int:
    from lookahead.config import load_config_or_exit
    from lookahead_clients.job_source import default_job_id, load_job, make_segments

    cfg = load_config_or_exit(args.config)
    try:
        src = load_job(args.source, list(cfg.machine.axes), _circuits(args.circuits))
        segments = make_segments(args.job or default_job_id(src.name), src.axes, src.points,
                                 args.chunk, args.fit or cfg.planner.fit, src.feeds, args.feed)
    except (ValueError, OSError) as exc:
        print(f"publish: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    say = (lambda msg: None) if args.quiet else (lambda msg: print(msg, file=sys.stderr))
    say(f"publish: job {segments[0].job}: {src.description}; {len(segments)} segments")
    return publish_job(cfg, segments, rate=args.rate, wait_s=args.wait_s,
                       timeout=args.timeout, say=say, progress=not args.quiet)


def publish_job(cfg, segments, rate: float = 0.0, wait_s: float = 10.0, timeout: float = 0.0,
                say=print, progress: bool = True) -> int:
    """Publish `segments` of one job and wait for its end; returns the exit status."""
    import queue

    from lookahead.bus import open_client_session
    from lookahead.progress import Progress
    from lookahead.protocol import Event, ProtocolError, Status, key
    from lookahead_clients.busio import close_session, publisher, subscribe, watch_liveliness

    job = segments[0].job
    start = time.monotonic()
    deadline = start + timeout if timeout > 0 else float("inf")
    inbox: queue.Queue = queue.Queue()
    session = open_client_session(cfg.zenoh)
    try:
        subscribe(session, key(cfg.ns, "events"), inbox)
        subscribe(session, key(cfg.ns, "status"), inbox)
        watch_liveliness(session, key(cfg.ns, "alive", "planner"), inbox)
        seg_pub = publisher(session, key(cfg.ns, "segments"))
        planner_up = False
        wait_deadline = min(deadline, start + wait_s)
        while not planner_up:
            try:
                planner_up = inbox.get(timeout=max(wait_deadline - time.monotonic(), 0.0)
                                       ).kind == "alive"
            except queue.Empty:
                say(f"publish: no planner alive on {key(cfg.ns, 'alive', 'planner')} "
                    f"after {wait_s:g} s")
                return EXIT_TIMEOUT
        time.sleep(0.2)  # let our subscriptions reach the service before the job starts
        published, executed = 0, 0
        interval = 1.0 / rate if rate > 0 else 0.0
        next_put = time.monotonic()
        bar = Progress(len(segments), f"job {job}")
        bar.enabled = bar.enabled and progress
        nl = "\n" if bar.enabled else ""  # end the progress bar's line first
        with bar:
            while True:
                now = time.monotonic()
                if published < len(segments) and now >= next_put:
                    seg_pub.put(segments[published].encode())
                    published += 1
                    next_put = now + interval if interval else now
                    if interval == 0.0:
                        continue  # burst: the rest right away
                if now > deadline:
                    say(f"{nl}publish: timed out after {timeout:g} s")
                    return EXIT_TIMEOUT
                wait = min(max(next_put - now, 0.0), 0.1) if published < len(segments) \
                    else 0.1
                try:
                    item = inbox.get(timeout=wait)
                except queue.Empty:
                    continue
                if item.kind == "gone":
                    say(f"{nl}publish: the planner went away during job {job}")
                    return EXIT_FAILED
                if item.kind != "put":
                    continue
                try:
                    if item.key.endswith("/status"):
                        status = Status.decode(item.payload)
                        if status.job == job:
                            done = max(published - status.queued, executed)
                            bar.update(done - executed)
                            executed = done
                        continue
                    event = Event.decode(item.payload)
                except ProtocolError:
                    continue
                if event.job not in (job, None):
                    continue
                if event.type == "job_finished" and event.job == job:
                    bar.update(len(segments) - executed)
                    aborted = bool(event.extra.get("aborted"))
                    say(f"{nl}publish: job {job} {'aborted' if aborted else 'finished'}: "
                        f"{event.extra['duration_s']:.3f} s of motion")
                    return EXIT_FAILED if aborted else 0
                if event.type in ("rejected", "fault"):
                    where = f" (segment {event.extra['seq']})" if "seq" in event.extra else ""
                    say(f"{nl}publish: job {job} {event.type}{where}: {event.extra['reason']}")
                    return EXIT_FAILED
    finally:
        close_session(session)
