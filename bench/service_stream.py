"""Benchmark of the streaming service; results to bench/results/service_stream.json.

1. first segment -> first batch latency (bus, fast and real-time mode, heuristic);
2. per-replan planning time, median and p99, both methods (engine, tube-1450, 100-point
   chunks);
3. real-time factor (motion time / wall time) of tube-9570 streamed in 100-point chunks
   through the bus in --fast mode, both methods;
4. CPU share of a `lookahead serve` process in real-time mode at dt = 1 ms (tube-1450);
5. a whole layer (45 circuits of tube-1450, 117541 points in 500-point segments, all sent
   at once) through the engine, LP: the wall time per 20 s of motion from start to end (flat
   = nothing grows with the job) and the cost of one status() (`--quick` skips this);
6. hold latency in real time, both methods (tube-9570): the motion already produced when a
   `hold` arrives (the batch the engine makes next, the first that can slow down, starts
   that far after the last sample the client had received; the machine adds the 50 ms
   lead), over 5 holds per job.

Run: /tmp/venv/bin/python bench/service_stream.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from lookahead.config import config_to_toml, default_config  # noqa: E402
from lookahead.geometry.winding import preset_points  # noqa: E402
from lookahead.stream.engine import Engine  # noqa: E402
from lookahead.stream.planners import make_planner  # noqa: E402
from service_harness import Harness, point_segments, service_config  # noqa: E402


class TimedPlanner:
    """Wraps a planner and records the wall time of every plan call (s)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.name = inner.name
        self.times: list[float] = []

    def plan(self, request):
        t = time.perf_counter()
        try:
            return self.inner.plan(request)
        finally:
            self.times.append(time.perf_counter() - t)


def latency(fast: bool) -> float:
    h = Harness(service_config("heuristic"), fast=fast)
    try:
        _, pts, _ = preset_points("tube-1450")
        segs = point_segments("lat", pts, [100] * (len(pts) // 100 + 1))
        t0 = time.monotonic()
        for seg in segs:
            h.send(seg)
        h.wait_for(lambda: bool(h.batches), 30, "first batch")
        return time.monotonic() - t0
    finally:
        h.close()


def replan_times(method: str) -> dict:
    cfg = default_config()
    planner = TimedPlanner(make_planner(method))
    eng = Engine(cfg, planner)
    _, pts, _ = preset_points("tube-1450")
    segs = point_segments("rp", pts, [100] * (len(pts) // 100 + 1))
    fed = 0
    while True:
        if fed < len(segs):
            eng.submit(segs[fed])
            fed += 1
        batch = eng.next_batch()
        if batch is not None and batch.final:
            break
    t = np.array(planner.times) * 1e3
    return {"plans": int(t.size), "median_ms": float(np.median(t)),
            "p99_ms": float(np.percentile(t, 99)), "max_ms": float(t.max()),
            "failed": eng.replan_failures}


def realtime_factor(method: str, preset: str) -> dict:
    h = Harness(service_config(method), fast=True)
    try:
        _, pts, _ = preset_points(preset)
        t0 = time.monotonic()
        for seg in point_segments("rtf", pts, [100] * (len(pts) // 100 + 1)):
            h.send(seg)
        batches = h.wait_final("rtf", timeout=3600)
        wall = time.monotonic() - t0
        motion = sum(b.n for b in batches) * h.cfg.machine.dt
        return {"preset": preset, "motion_s": motion, "wall_s": wall,
                "realtime_factor": motion / wall}
    finally:
        h.close()


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cpu_share(method: str) -> dict:
    cfg = service_config(method)
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
        f.write(config_to_toml(cfg))
    proc = subprocess.Popen([sys.executable, "-m", "lookahead", "serve", "--config", f.name,
                             "--log-level", "WARNING"])
    try:
        time.sleep(1.5)
        h = Harness.__new__(Harness)
        client_cfg = cfg
        # a client-only harness: no service thread of its own
        from lookahead.bus import open_client_session
        from lookahead.protocol import SetpointBatch, key

        session = open_client_session(client_cfg.zenoh)
        got: list[SetpointBatch] = []
        sub = session.declare_subscriber(
            key(cfg.ns, "setpoints"),
            lambda s: got.append(SetpointBatch.decode(s.payload.to_bytes())))
        import zenoh

        pub = session.declare_publisher(key(cfg.ns, "segments"),
                                        congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.6)
        _, pts, _ = preset_points("tube-1450")
        c0, t0 = _cpu_s(proc.pid), time.monotonic()
        for seg in point_segments("cpu", pts, [100] * (len(pts) // 100 + 1)):
            pub.put(seg.encode())
        while not any(b.final for b in got) and time.monotonic() - t0 < 120:
            time.sleep(0.05)
        c1, t1 = _cpu_s(proc.pid), time.monotonic()
        sub.undeclare()
        session.close()
        del h
        return {"method": method, "wall_s": t1 - t0, "cpu_s": c1 - c0,
                "cpu_share": (c1 - c0) / (t1 - t0), "samples": sum(b.n for b in got)}
    finally:
        proc.terminate()
        proc.wait(timeout=40)
        os.unlink(f.name)


def hold_latency(method: str, holds: int = 5) -> dict:
    """Real time: for each hold, the sample index k0 of the batch listing it (its
    `commands`) minus the last sample the client had received when it sent it (ms)."""
    h = Harness(service_config(method), fast=False)
    try:
        _, pts, _ = preset_points("tube-9570")
        for seg in point_segments("hold", pts, [500] * (len(pts) // 500 + 1)):
            h.send(seg)
        h.wait_for(lambda: len(h.batches) > 100, 30, "1 s of motion")
        ahead_ms = []
        for _ in range(holds):
            with h.lock:
                k_recv = max(b.k0 + b.n - 1 for b in h.batches)
            assert h.command("hold").ok
            h.wait_for(lambda: any(c[0] == "hold" for b in h.batches[-300:]
                                   for c in b.commands), 10, "the hold's batch")
            with h.lock:
                k_hold = next(b.k0 for b in h.batches if any(c[0] == "hold"
                                                             for c in b.commands))
                h.batches[:] = [b for b in h.batches if b.k0 > k_hold]  # next hold: fresh
            ahead_ms.append((k_hold - 1 - k_recv) * h.cfg.machine.dt * 1e3)
            time.sleep(0.8)  # at rest
            assert h.command("resume").ok
            time.sleep(1.5)  # back to speed
        return {"method": method, "holds": holds, "ahead_ms": ahead_ms,
                "ahead_ms_median": float(np.median(ahead_ms)),
                "lead_ms": h.cfg.service.lead_s * 1e3}
    finally:
        h.close()


def long_job(method: str = "lp", circuits: int = 45, chunk: int = 500) -> dict:
    """A layer through the engine; wall time per 20 s of motion and of a status() call."""
    cfg = default_config()
    _, pts, _ = preset_points("tube-1450", circuits=circuits)
    segs = point_segments("layer", pts, [chunk] * (len(pts) // chunk + 1))
    eng = Engine(cfg, make_planner(method))
    t0 = time.perf_counter()
    for seg in segs:
        eng.submit(seg)
    status_ms = []
    per_20s, samples, mark, last = [], 0, 20.0, time.perf_counter()
    while True:
        batch = eng.next_batch()
        if batch is None:
            continue
        samples += batch.n
        if samples * cfg.machine.dt >= mark:
            t = time.perf_counter()
            eng.status()
            status_ms.append(1e3 * (time.perf_counter() - t))
            per_20s.append(t - last)
            last, mark = time.perf_counter(), mark + 20.0
        if batch.final:
            break
    wall = time.perf_counter() - t0
    motion = samples * cfg.machine.dt
    return {"method": method, "points": len(pts), "segments": len(segs),
            "motion_s": motion, "wall_s": wall, "realtime_factor": motion / wall,
            "wall_per_20s_motion": per_20s, "status_ms_median": float(np.median(status_ms))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true",
                    help="skip the LP on tube-9570 and the layer")
    args = ap.parse_args()
    out: dict = {"machine": {"cpus": os.cpu_count()}}
    out["latency_first_batch_s"] = {"fast": latency(True), "realtime": latency(False)}
    print(out["latency_first_batch_s"], flush=True)
    out["replan"] = {m: replan_times(m) for m in ("heuristic", "lp")}
    print(out["replan"], flush=True)
    methods = ("heuristic",) if args.quick else ("heuristic", "lp")
    out["realtime_factor_tube_9570_fast"] = {m: realtime_factor(m, "tube-9570")
                                             for m in methods}
    print(out["realtime_factor_tube_9570_fast"], flush=True)
    out["cpu_share_realtime"] = {m: cpu_share(m) for m in ("heuristic", "lp")}
    print(out["cpu_share_realtime"], flush=True)
    out["hold_latency_realtime"] = {m: hold_latency(m) for m in ("heuristic", "lp")}
    print(out["hold_latency_realtime"], flush=True)
    if not args.quick:
        out["layer_engine"] = long_job()
        print(out["layer_engine"], flush=True)
    dest = ROOT / "bench" / "results" / "service_stream.json"
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {dest}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
