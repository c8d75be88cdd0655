"""A 100k-line fiberpath-style program on the three-drive winder (issue 17): plan time and
x real time of `lookahead plan`, and the whole chain `publish -> serve --fast -> winder
--fast` with the service's peak memory sampled while it runs. Results to
bench/results/long_program.json.

    .venv/bin/python bench/long_program.py [--lines 100000] [--methods heuristic,lp]
        [--no-stream] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lookahead.bus import free_tcp_endpoint
from lookahead_clients.cam_program import WindingProgram, gcode

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results" / "long_program.json"


def program(lines: int) -> WindingProgram:
    """A hoop layer and a helical layer on a 1450 mm tube (R 100 mm, 45 deg) with about
    `lines` lines (each circuit: 2 x 1450 one-mm moves + 5 lines)."""
    base = WindingProgram(length=1450.0, radius=100.0, angle_deg=45.0, circuits=1,
                          hoop=True, band=10.0)
    hoop_lines = int(1450.0 / base.band) * base.hoop_steps + 2
    circuits = max(1, round((lines - hoop_lines - 7) / (2 * 1450 + 5)))
    return WindingProgram(**{**base.__dict__, "circuits": circuits})


def vm_hwm_mb(pid: int) -> float:
    """Peak resident memory (MB) of process `pid` so far (/proc, Linux)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return float("nan")
    m = re.search(r"VmHWM:\s+(\d+) kB", text)
    return int(m.group(1)) / 1024 if m else float("nan")


def lookahead(*argv, env=None, stderr=subprocess.PIPE, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "lookahead", *argv], env=env,
                            stdout=subprocess.PIPE, stderr=stderr, text=True, **kw)


def plan(job: Path, method: str) -> dict:
    """`lookahead plan` on the program: wall time, its summary numbers, peak memory."""
    t0 = time.perf_counter()
    proc = lookahead("plan", str(job), "--config", "winder3", "--method", method)
    peak = 0.0
    while proc.poll() is None:
        peak = max(peak, vm_hwm_mb(proc.pid))
        time.sleep(0.2)
    out, err = proc.communicate()
    wall = time.perf_counter() - t0

    def number(label: str) -> float | None:
        m = re.search(rf"^{label}\s+([0-9.]+)", out, re.M)
        return float(m.group(1)) if m else None

    duration, program_s = number("duration"), number("program says")
    compute = re.search(r"^compute\s+([0-9.]+) ms", out, re.M)
    return {"method": method, "exit": proc.returncode, "wall_s": wall,
            "duration_s": duration, "program_says_s": program_s,
            "compute_s": float(compute.group(1)) / 1e3 if compute else None,
            "x_real_time": duration / (float(compute.group(1)) / 1e3)
            if duration and compute else None,
            "violations": number("violations"), "fallbacks": number("fallbacks"),
            "peak_rss_mb": peak, "stderr_tail": err.strip().splitlines()[-3:]}


def stream(job: Path, method: str, realtime: bool = False) -> dict:
    """publish -> serve --fast -> winder --fast (`realtime`: both on the wall clock, the
    program's whole motion time); the service's peak memory over time."""
    fast = () if realtime else ("--fast",)
    # RUST_LOG: zenoh's own warnings (a transport closed, a lease expired) in the logs
    env = {**os.environ, "LOOKAHEAD_ZENOH_LISTEN": free_tcp_endpoint(),
           "LOOKAHEAD_PLANNER_METHOD": method, "PYTHONUNBUFFERED": "1",
           "RUST_LOG": os.environ.get("RUST_LOG", "zenoh=warn")}
    env.pop("LOOKAHEAD_ZENOH_CONNECT", None)
    tmp = Path(tempfile.mkdtemp())
    report = tmp / "report.json"
    # stderr to files, not pipes: nothing reads a pipe before the end, and a full one
    # would block the process writing to it
    logs = {name: (tmp / f"{name}.log").open("w+") for name in ("service", "winder")}
    service = lookahead("serve", "--config", "winder3", *fast, "--log-level", "WARNING",
                        env=env, stderr=logs["service"])
    winder = lookahead("winder", "--config", "winder3", *fast, "--jobs", "1",
                       "--report-json", str(report), env=env, stderr=logs["winder"])
    time.sleep(3.0)
    t0 = time.perf_counter()
    pub = lookahead("publish", str(job), "--config", "winder3", "--quiet", "--chunk", "200",
                    "--wait-s", "30", env=env)
    memory = []
    while pub.poll() is None:
        memory.append((round(time.perf_counter() - t0, 1), vm_hwm_mb(service.pid)))
        time.sleep(1.0)
    wall = time.perf_counter() - t0
    winder.wait(timeout=7200 if realtime else 120)  # real time: the whole motion time
    for p in (service, winder):
        if p.poll() is None:
            p.terminate()
    service.communicate(timeout=30)
    winder.communicate(timeout=30)
    text = {}
    for name, f in logs.items():
        f.seek(0)
        text[name] = f.read()
        f.close()
    service_err = text["service"]
    zenoh_log = [f"{name}: {ln}" for name, t in text.items()
                 for ln in (re.sub(r"\x1b\[[0-9;]*m", "", raw) for raw in t.splitlines())
                 if re.search(r" (WARN|ERROR) ", ln)]
    rep = json.loads(report.read_text())[-1] if report.exists() else {}
    duration = rep.get("duration_s")
    return {"method": method, "publish_exit": pub.returncode, "wall_s": wall,
            "duration_s": duration, "x_real_time": duration / wall if duration else None,
            "violations": rep.get("violations"), "gaps": rep.get("gaps"),
            "fallbacks": rep.get("fallbacks"), "clean": rep.get("clean"),
            "underruns": rep.get("underruns"), "max_lateness_s": rep.get("max_lateness_s"),
            "late_replans": rep.get("late_replans"),
            "service_peak_rss_mb": max((m for _, m in memory), default=None),
            "service_rss_over_time": memory[:: max(1, len(memory) // 40)],
            "service_warning_count": sum("WARNING" in ln for ln in service_err.splitlines()),
            "service_warnings": [ln for ln in service_err.splitlines() if "WARNING" in ln][:20],
            "zenoh_warnings": zenoh_log[:40]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=100_000)
    ap.add_argument("--methods", default="heuristic,lp")
    ap.add_argument("--no-stream", action="store_true")
    ap.add_argument("--no-plan", action="store_true")
    ap.add_argument("--realtime", action="store_true",
                    help="also stream in real time (the program's motion time, ~50 min)")
    ap.add_argument("--update", action="store_true",
                    help="keep the results file's other entries")
    ap.add_argument("--out", default=str(OUT), help="results file (default: %(default)s)")
    args = ap.parse_args()
    prog = program(args.lines)
    text = gcode(prog)
    job = Path(tempfile.mkdtemp()) / "long.gcode"
    job.write_text(text)
    old = json.loads(Path(args.out).read_text()) if args.update else {}
    result = {"plan": [], "stream": [], "realtime": [], **old,
              "lines": len(text.splitlines()), "program": prog.__dict__}
    print(f"{result['lines']} lines", file=sys.stderr)

    def put(kind: str, row: dict) -> None:
        result[kind] = [r for r in result[kind] if r["method"] != row["method"]] + [row]
        print(json.dumps(row)[:600], file=sys.stderr)

    for method in args.methods.split(","):
        if not args.no_plan:
            put("plan", plan(job, method))
        if not args.no_stream:
            put("stream", stream(job, method))
        if args.realtime:
            put("realtime", stream(job, method, realtime=True))
    Path(args.out).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
