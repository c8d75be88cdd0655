"""Every fast-corpus path through the whole service in real time (bus included): does the
machine ever wait for the service?

Per path and method: a `PlannerService` in real time (`lookahead serve` without `--fast`,
in a thread of this process, zenoh peers on loopback) with the path's machine
configuration; all its segments published at once; the setpoint batches collected with
their arrival times. Judged as the winder judges them: a batch is an underrun when it
arrives after its first sample is due (the first batch's arrival plus k0 * dt, plus the
50 ms publishing lead the service keeps); the finite-difference checker on the stream;
gaps; and the service's own counts from `job_finished` (fallbacks, LP handovers, replans
dropped as late, `dropped`). A dropped replan is not an underrun (the plan in force goes
on) but an unplanned slowdown: it counts against CLEAN, as the winder counts it.

    .venv/bin/python bench/realtime_corpus.py [--methods lp,heuristic] [--paths GLOB,...]
        [--load N]

--load N runs N busy processes beside the service (a shared, noisy machine: with N = 1
on 2 cores, every core is busy while the service plans).

Results: bench/results/realtime_corpus.json (wall time ~ the corpus's motion time per
method).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import multiprocessing as mp
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path as FsPath

import numpy as np

ROOT = FsPath(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.corpus import load_corpus  # noqa: E402
from lookahead.bus import free_tcp_endpoint, open_client_session, with_endpoints  # noqa: E402
from lookahead.checker import LimitChecker  # noqa: E402
from lookahead.protocol import Event, SetpointBatch, key  # noqa: E402
from lookahead.service import PlannerService  # noqa: E402

OUT = ROOT / "bench" / "results" / "realtime_corpus.json"
#: the bus's set-up before publishing (s), and the longest a job may take beyond its
#: motion (s): planning its first window, the real-time buffer
CONNECT_S = 0.6
SLACK_S = 60.0


def run(p, method: str) -> dict:
    import zenoh

    cfg = p.config
    cfg = replace(cfg, zenoh=with_endpoints(cfg.zenoh, listen=[free_tcp_endpoint()]),
                  planner=replace(cfg.planner, method=method))
    service = PlannerService(cfg, fast=False)
    service.open()
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    client = open_client_session(cfg.zenoh)
    lock = threading.Lock()
    arrivals: list[tuple[float, SetpointBatch]] = []
    events: list[Event] = []
    done = threading.Event()

    def on_batch(sample) -> None:
        batch = SetpointBatch.decode(sample.payload.to_bytes())
        with lock:
            arrivals.append((time.monotonic(), batch))
        if batch.final:
            done.set()

    def on_event(sample) -> None:
        with lock:
            events.append(Event.decode(sample.payload.to_bytes()))

    subs = [client.declare_subscriber(key(cfg.ns, "setpoints"), on_batch),
            client.declare_subscriber(key(cfg.ns, "events"), on_event)]
    pub = client.declare_publisher(key(cfg.ns, "segments"),
                                   congestion_control=zenoh.CongestionControl.BLOCK)
    time.sleep(CONNECT_S)
    t_start = time.monotonic()
    for seg in p.segments:
        pub.put(seg.encode())
    finished = done.wait(timeout=SLACK_S + 1200.0)
    time.sleep(0.3)  # job_finished follows the final batch
    wall = time.monotonic() - t_start
    service.request_shutdown()
    thread.join(timeout=30)
    for sub in subs:
        sub.undeclare()
    client.close()
    service.close()
    with lock:
        got = sorted(arrivals, key=lambda ab: ab[1].seq)
        evs = list(events)
    dt = cfg.machine.dt
    lead = cfg.service.lead_s
    checker = LimitChecker(cfg.machine.limits, dt)
    gaps, k, late, underruns, dropped = 0, 0, -np.inf, 0, 0
    t0 = got[0][0] + lead if got else 0.0  # sample 0 due: one lead after batch 0 arrived
    for arrival, batch in got:
        if batch.k0 != k:
            gaps += 1
        k = batch.k0 + batch.n
        checker.feed(batch.pos)
        lateness = arrival - (t0 + batch.k0 * dt)
        late = max(late, lateness)
        underruns += lateness > 0
        dropped += len(batch.dropped)
    fin = [e for e in evs if e.type == "job_finished"]
    extra = fin[-1].extra if fin else {}
    violations = checker.report().violations
    row = {"finished": bool(finished and got and got[-1][1].final), "motion_s": k * dt,
           "wall_s": wall, "batches": len(got), "gaps": gaps, "underruns": underruns,
           "max_lateness_ms": 1e3 * late if got else None, "violations": violations,
           "fallbacks": extra.get("fallbacks"), "handovers": extra.get("handovers"),
           "late_replans": extra.get("late_replans"), "dropped": dropped,
           "stats_max_late_ms": 1e3 * service.stats.max_late_s}
    row["clean"] = bool(row["finished"] and not gaps and not underruns and not violations
                        and not row["fallbacks"] and not dropped)
    return row


def _spin() -> None:
    """A busy process (`--load`)."""
    x = 0
    while True:
        x = (x * 1103515245 + 12345) & 0xFFFFFFFF


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--methods", default="lp,heuristic")
    ap.add_argument("--paths", default="*")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--load", type=int, default=0, help="busy processes beside the service")
    args = ap.parse_args()
    globs = args.paths.split(",")
    methods = [m for m in args.methods.split(",") if m]
    out: dict = {"meta": {"methods": methods, "load": args.load, "time_utc": time.strftime(
        "%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, "paths": {}}
    spinners = [mp.get_context("spawn").Process(target=_spin, daemon=True)
                for _ in range(args.load)]
    for proc in spinners:
        proc.start()
    for p in load_corpus("fast", skip_long=True):
        if not any(fnmatch.fnmatch(p.name, g) for g in globs):
            continue
        row = out["paths"][p.name] = {}
        for method in methods:
            r = row[method] = run(p, method)
            print(f"{p.name:40s} {method:9s} {'CLEAN' if r['clean'] else 'NOT CLEAN':9s} "
                  f"motion {r['motion_s']:7.2f} s  underruns {r['underruns']} (latest "
                  f"{r['max_lateness_ms']:+.0f} ms)  dropped {r['dropped']}  fallbacks "
                  f"{r['fallbacks']}  handovers {r['handovers']}  viol {r['violations']}  "
                  f"gaps {r['gaps']}", file=sys.stderr, flush=True)
    for proc in spinners:
        proc.terminate()
    FsPath(args.out).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
