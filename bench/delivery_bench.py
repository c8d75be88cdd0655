"""Benchmark of delivery (issue 16); results to bench/results/delivery.json.

1. Recovery time from a lost segment: our publisher drops 5 % of its first puts (seeded)
   of corpus jobs (points, 20-point segments) streamed to a real-time service on loopback;
   for every gap, the time from the service's first `missing` for it (sent in the loop
   pass that took in the segment revealing the gap) to the resent segment being taken in.
   Median, p99, max over all gaps; per job also whether it starved and that its
   setpoints pass the checker.
2. Throughput into the service: N segments sent by our publisher (no pacing: window = N)
   while a lead-in job starves, so the service does nothing but take them in; segments/s
   and points/s from the first put to `next_seq` = N, for chunk sizes and fits.

Instrumentation wraps the engine's `announce_missing` and `submit` in this script (the
service is unchanged). Run: .venv/bin/python bench/delivery_bench.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

from bench.corpus import load_corpus  # noqa: E402
from delivery_harness import PublisherThread, bus_config, lead_in, rechunk  # noqa: E402
from lookahead.checker import LimitChecker  # noqa: E402
from lookahead.config import default_config  # noqa: E402
from lookahead.protocol import Status  # noqa: E402
from lookahead_clients.job_source import make_segments  # noqa: E402
from service_harness import Harness  # noqa: E402

RESULTS = ROOT / "bench" / "results" / "delivery.json"
RECOVERY_PATHS = ("w-issue-tube1450-R100-a45-sine-2mm", "cam-style-R50-a45-L200",
                  "w-hoop-R40-band8-2mm", "c-fourier-xc-3000pts", "c-cycloid-near-cusp-a0p995")


class GapClock:
    """Wraps a service's engine: when each (job, seq) was first announced missing and when
    it was taken in (monotonic s)."""

    def __init__(self, engine) -> None:
        self.engine = engine
        self.announced: dict[tuple[str, int], float] = {}
        self.filled: dict[tuple[str, int], float] = {}
        announce, submit = engine.announce_missing, engine.submit

        def timed_announce(now_s):
            events = announce(now_s)
            t = time.monotonic()
            for e in events:
                self.announced.setdefault((e.job, e.extra["seq"]), t)
            return events

        def timed_submit(seg, now_s=None):
            events = submit(seg, now_s)
            t = time.monotonic()
            job = engine._jobs.get(seg.job)
            # a resend may release waiting segments whose own gaps it closes too
            for key in [k for k in self.announced if k[0] == seg.job and k not in self.filled]:
                if job is None or key[1] in job.order.taken:
                    self.filled[key] = t
            return events

        engine.announce_missing = timed_announce
        engine.submit = timed_submit

    def recoveries_ms(self) -> list[float]:
        return [1e3 * (self.filled[k] - t) for k, t in self.announced.items()
                if k in self.filled]


def recovery(quick: bool) -> dict:
    paths = [p for p in load_corpus("fast") if p.name in RECOVERY_PATHS]
    if quick:
        paths = paths[:2]
    rows, all_ms = [], []
    for p in paths:
        h = Harness(bus_config(p.config, "heuristic"), fast=False)
        try:
            clock = GapClock(h.service.engine)
            segs = rechunk(p.segments, f"rec-{p.name}"[:64], 20)
            pub = PublisherThread(h.cfg, segs, timeout=300.0, drop_rate=0.05, seed=16)
            rc = pub.join(320.0)
            batches = h.wait_final(segs[0].job, timeout=60)
            checker = LimitChecker(h.cfg.machine.limits, h.cfg.machine.dt)
            for b in batches:
                checker.feed(b.pos)
            ms = clock.recoveries_ms()
            all_ms += ms
            rows.append({
                "path": p.name, "segments": len(segs), "rc": rc,
                "dropped": pub.stats["dropped"], "gaps_recovered": len(ms),
                "gaps_announced": len(clock.announced),
                "recovery_ms_median": float(np.median(ms)) if ms else None,
                "recovery_ms_max": float(np.max(ms)) if ms else None,
                "starved_events": len(h._events_of("starved", segs[0].job)),
                "violations": checker.report().violations,
                "faults": len(h._events_of("fault", None)),
                "max_late_s": h.service.stats.max_late_s,
                "motion_s": sum(b.n for b in batches) * h.cfg.machine.dt})
            print(rows[-1], flush=True)
        finally:
            h.close()
    ms = np.array(all_ms)
    return {"mode": "real-time service, heuristic planner, loopback, drop 5 % of first puts",
            "recovery_ms_median": float(np.median(ms)) if ms.size else None,
            "recovery_ms_p99": float(np.percentile(ms, 99)) if ms.size else None,
            "recovery_ms_max": float(ms.max()) if ms.size else None,
            "gaps": int(ms.size), "jobs": rows}


def throughput(quick: bool) -> list[dict]:
    cases = [(1, "smooth", 5000), (1, "cubic", 1000), (20, "cubic", 1000),
             (200, "cubic", 200)]
    if quick:
        cases = cases[:2]
    out = []
    for chunk, fit, n_seg in cases:
        h = Harness(bus_config(default_config(), "heuristic"), fast=True)
        try:
            n_pts = chunk * n_seg
            t = np.linspace(0.0, 1.0, n_pts)
            pts = np.column_stack([200.0 * t, 90.0 * np.sin(2 * np.pi * t)])
            segs = make_segments("tput", ["X", "C"], pts, chunk, fit)
            first, _ = lead_in("lead", np.array([-50.0, 0.0]), pts[0], ("X", "C"))
            h.send(first)
            h.wait_event("starved", "lead", timeout=30)
            t0 = time.monotonic()
            pub = PublisherThread(h.cfg, segs, timeout=600.0, window=len(segs))
            while True:
                st = Status.decode(h.status_bytes())
                if st.receiving == "tput" and st.next_seq == len(segs):
                    break
                time.sleep(0.01)
            wall = time.monotonic() - t0 - 0.2  # the publisher's settling sleep
            h.command("abort")
            pub.join(60.0)
            out.append({"points_per_segment": chunk, "fit": fit, "segments": len(segs),
                        "wall_s": wall, "segments_per_s": len(segs) / wall,
                        "points_per_s": n_pts / wall,
                        "max_incoming": h.service.stats.max_incoming})
            print(out[-1], flush=True)
        finally:
            h.close()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer paths and cases")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    result = {"recovery": recovery(args.quick), "throughput": throughput(args.quick),
              "quick": args.quick}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
