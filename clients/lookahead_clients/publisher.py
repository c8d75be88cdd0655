"""`lookahead publish PRESET|FILE`: send one job's segments to the planner service.

Waits for `NS/alive/planner`, publishes the job as `points` segments of `--chunk` points
(as fast as the service takes them, or `--rate` segments per second), shows the job's
progress (segments executed, from `NS/status`) and waits for the job's end on `NS/events`.
Delivery (PROTOCOL.md "Delivery"): reliable puts with blocking congestion control, every
segment kept until the job ends, resent when a `missing` event names it or the service
turned it away while full; at most `--window` segments beyond the status' `next_seq`.
`--drop-rate` skips that fraction of the first puts on purpose, to show the recovery.
Exit status: 0 on `job_finished`, 1 on `rejected` / `fault` / the planner going away (the
reason on stderr), 2 on a bad source or configuration, 4 on a timeout.
"""

from __future__ import annotations

import argparse
import sys
import time

from lookahead_clients.delivery import WINDOW

EXIT_FAILED, EXIT_BAD_INPUT, EXIT_TIMEOUT = 1, 2, 4
#: while the window is full, ask the service for its status this often (s) rather than
#: wait for the next published one (status_hz, 10 Hz by default)
STATUS_POLL_S = 0.02


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
    p.add_argument("--fit", choices=("cubic", "pchip", "linear", "smooth"), default=None,
                   help="curve through the points (default: smooth for G-code, else the "
                        "config's planner.fit)")
    p.add_argument("--feed", type=float, default=None, help="path speed cap (units/s)")
    p.add_argument("--dialect", choices=("marlin", "rs274"), default=None,
                   help="G-code dialect (default: the config's gcode.dialect)")
    p.add_argument("--ignore-letters", default="", metavar="LETTERS",
                   help="G-code axis letters to drop, e.g. B (with the config's gcode.ignore)")
    p.add_argument("--circuits", default=None,
                   help="presets: number of circuits or 'layer' (default 1)")
    p.add_argument("--wait-s", type=float, default=10.0,
                   help="how long to wait for the planner to appear (default 10 s)")
    p.add_argument("--timeout", type=float, default=0.0,
                   help="give up after this many seconds in all (default 0: never)")
    p.add_argument("--quiet", action="store_true", help="no progress bar or messages")
    p.add_argument("--window", type=int, default=WINDOW,
                   help=f"segments in flight beyond the service's next_seq (default {WINDOW})")
    p.add_argument("--drop-rate", type=float, default=0.0,
                   help="demo/test: skip this fraction of the first puts (the service asks "
                   "for them again with `missing`)")
    p.add_argument("--seed", type=int, default=None, help="seed of --drop-rate / --reorder")
    p.add_argument("--reorder", type=int, default=0,
                   help="test: shuffle the first puts in blocks of this many segments")
    p.add_argument("--duplicate", action="store_true", help="test: put every segment twice")
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
        src = load_job(args.source, list(cfg.machine.axes), _circuits(args.circuits),
                       cfg.gcode_options(ignore=args.ignore_letters, dialect=args.dialect))
        segments = make_segments(args.job or default_job_id(src.name), src.axes, src.points,
                                 args.chunk, args.fit or src.fit or cfg.planner.fit,
                                 src.feeds, args.feed, src.tolerances)
    except (ValueError, OSError) as exc:
        print(f"publish: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    say = (lambda msg: None) if args.quiet else (lambda msg: print(msg, file=sys.stderr))
    say(f"publish: job {segments[0].job}: {src.description}; {len(segments)} segments")
    if not 0.0 <= args.drop_rate < 1.0 or args.window < 1:
        print("publish: --drop-rate must be in [0, 1) and --window >= 1", file=sys.stderr)
        return EXIT_BAD_INPUT
    return publish_job(cfg, segments, rate=args.rate, wait_s=args.wait_s,
                       timeout=args.timeout, say=say, progress=not args.quiet,
                       window=args.window, drop_rate=args.drop_rate, seed=args.seed,
                       reorder=args.reorder, duplicate=args.duplicate)


def publish_job(cfg, segments, rate: float = 0.0, wait_s: float = 10.0, timeout: float = 0.0,
                say=print, progress: bool = True, window: int = WINDOW,
                drop_rate: float = 0.0, seed: int | None = None, reorder: int = 0,
                duplicate: bool = False, stats: dict | None = None) -> int:
    """Publish `segments` of one job and wait for its end; returns the exit status.
    `stats`, if given, receives the Outbox counters (resends, drops, refusals)."""
    import queue
    from dataclasses import asdict

    from lookahead.bus import open_client_session, reliable_publisher
    from lookahead.progress import Progress
    from lookahead.protocol import Event, ProtocolError, Status, key
    from lookahead_clients.busio import close_session, query_once, subscribe, watch_liveliness
    from lookahead_clients.delivery import Outbox

    job = segments[0].job
    outbox = Outbox(job, [seg.encode() for seg in segments], window=window,
                    drop_rate=drop_rate, seed=seed, reorder=reorder, duplicate=duplicate)
    start = time.monotonic()
    deadline = start + timeout if timeout > 0 else float("inf")
    inbox: queue.Queue = queue.Queue()
    session = open_client_session(cfg.zenoh)
    try:
        subscribe(session, key(cfg.ns, "events"), inbox)
        subscribe(session, key(cfg.ns, "status"), inbox)
        watch_liveliness(session, key(cfg.ns, "alive", "planner"), inbox)
        seg_pub = reliable_publisher(session, key(cfg.ns, "segments"))
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
        executed = 0
        interval = 1.0 / rate if rate > 0 else 0.0
        next_put = time.monotonic()
        last_poll = 0.0
        bar = Progress(len(segments), f"job {job}")
        bar.enabled = bar.enabled and progress
        nl = "\n" if bar.enabled else ""  # end the progress bar's line first

        def on_status(payload: bytes, now: float) -> None:
            nonlocal executed
            try:
                status = Status.decode(payload)
            except ProtocolError:
                return
            outbox.on_status(status.receiving, status.next_seq, status.accepting, now)
            if status.job == job:
                done = max(outbox.next_seq - status.queued, executed)
                bar.update(done - executed)
                executed = done

        with bar:
            while True:
                now = time.monotonic()
                allowed = None
                if interval:
                    allowed = 1 if now >= next_put else 0
                first_before = outbox.stats.first_puts
                for payload in outbox.due(now, allowed):
                    seg_pub.put(payload)
                if interval and outbox.stats.first_puts > first_before:
                    next_put = now + interval
                if now > deadline:
                    say(f"{nl}publish: timed out after {timeout:g} s")
                    return EXIT_TIMEOUT
                if outbox.blocked and now - last_poll >= STATUS_POLL_S:
                    last_poll = now
                    reply = query_once(session, key(cfg.ns, "status"), timeout=1.0)
                    if reply is not None:
                        on_status(reply, time.monotonic())
                    continue
                wait = 0.1
                if not outbox.all_first_put and not outbox.blocked:
                    wait = min(max(next_put - now, 0.0), 0.1) if interval else 0.0
                elif outbox.blocked:
                    wait = STATUS_POLL_S
                try:
                    item = inbox.get(timeout=wait) if wait > 0 else inbox.get_nowait()
                except queue.Empty:
                    continue
                if item.kind == "gone":
                    say(f"{nl}publish: the planner went away during job {job}")
                    return EXIT_FAILED
                if item.kind != "put":
                    continue
                if item.key.endswith("/status"):
                    on_status(item.payload, item.t)
                    continue
                try:
                    event = Event.decode(item.payload)
                except ProtocolError:
                    continue
                if event.job != job:
                    continue
                if event.type == "missing":
                    outbox.on_missing(int(event.extra["seq"]), item.t)
                    continue
                if event.type == "rejected" and event.extra.get("retry"):
                    seq = event.extra.get("seq")
                    if isinstance(seq, int):
                        outbox.on_refused(seq)
                    continue
                if event.type == "job_finished":
                    bar.update(len(segments) - executed)
                    aborted = bool(event.extra.get("aborted"))
                    say(f"{nl}publish: job {job} {'aborted' if aborted else 'finished'}: "
                        f"{event.extra['duration_s']:.3f} s of motion")
                    st = outbox.stats
                    resent = st.resent_missing + st.resent_refused + st.resent_stalled
                    if st.dropped or resent:
                        say(f"publish: delivery: {st.dropped} first puts dropped on purpose, "
                            f"{st.missing_events} missing events, {st.refused} refused while "
                            f"full, {resent} segments resent")
                    return EXIT_FAILED if aborted else 0
                if event.type in ("rejected", "fault"):
                    where = f" (segment {event.extra['seq']})" if "seq" in event.extra else ""
                    say(f"{nl}publish: job {job} {event.type}{where}: {event.extra['reason']}")
                    return EXIT_FAILED
    finally:
        if stats is not None:
            stats.update(asdict(outbox.stats))
        close_session(session)
