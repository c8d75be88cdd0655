"""`lookahead demo`: the planner service, the simulated winder and the publisher together.

Starts `lookahead serve`, `lookahead winder --jobs 1` and, once both are alive on the bus,
`lookahead publish PRESET` (default tube-1450) as subprocesses on a loopback endpoint
(tcp/127.0.0.1:7447, or a free port if that one is busy; passed to all three by
LOOKAHEAD_ZENOH_LISTEN). Shows the publisher's progress, then the winder's report (winding
time, peak fraction of each limit, violations, fibre-angle error) and the plot it wrote.
Exit status 0 only if the report is clean. The subprocesses are always stopped (also on
Ctrl-C, failure or `--timeout`); the service's log is kept in the output directory.
`--monitor` also starts `lookahead monitor` beside them and prints its address (a live web
page of the run).

`--machine NAME` runs a shipped machine (`winder2`, `winder3`: X, C and the delivery head
B; `winder4`: with a cross-feed Y) or a configuration file. A machine other than the
two-drive winder winds a fiberpath-style G-code program written for it
(`lookahead_clients.cam_program`, one helical circuit; `--preset` picks another job).
"""

from __future__ import annotations

import argparse
import sys

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def add_parser(sub: argparse._SubParsersAction, name: str, help_text: str
               ) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help_text, description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--fast", action="store_true",
                   help="no real-time pacing: plan and execute as fast as possible")
    p.add_argument("--config", "--machine", dest="config", metavar="MACHINE",
                   help="machine configuration: a TOML file or a shipped machine (winder2, "
                        "winder3, winder4; default: the built-in two-drive winder)")
    p.add_argument("--preset", default=None,
                   help="job to wind: a preset, points or G-code file (default tube-1450 on "
                        "the two-drive winder, else a generated fiberpath-style program)")
    p.add_argument("--out-dir", help="where the plot, report and logs go (default: a new "
                   "temporary directory)")
    p.add_argument("--timeout", type=float, default=600.0,
                   help="give up after this many seconds (default 600)")
    p.add_argument("--monitor", action="store_true",
                   help="also start `lookahead monitor` (a live web page of the run) and "
                        "print its address; on a terminal it stays up after the job until "
                        "Enter")
    p.add_argument("--monitor-port", type=int, default=8470,
                   help="the monitor's HTTP port (default 8470, a free one if busy)")
    return p


def _port_free(endpoint: str) -> bool:
    import socket

    host, port = endpoint.split("/", 1)[1].rsplit(":", 1)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        try:
            sock.bind((host, int(port)))
        except OSError:
            return False
    return True


def _interrupt(*_args) -> None:
    raise KeyboardInterrupt  # SIGTERM: clean up like on Ctrl-C


def pick_endpoint() -> str:
    """The default service endpoint if its port is free, else a free loopback port."""
    from lookahead.bus import free_tcp_endpoint

    return DEFAULT_ENDPOINT if _port_free(DEFAULT_ENDPOINT) else free_tcp_endpoint()


def run(args: argparse.Namespace) -> int:
    import os
    import signal
    import tempfile

    from lookahead_clients.processes import ProcessGroup

    endpoint = os.environ.get("LOOKAHEAD_ZENOH_LISTEN") or pick_endpoint()
    os.environ["LOOKAHEAD_ZENOH_LISTEN"] = endpoint  # this process's session too
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    out_dir = args.out_dir or tempfile.mkdtemp(prefix="lookahead-demo-")
    os.makedirs(out_dir, exist_ok=True)
    args.preset = args.preset or default_job(args.config, out_dir)
    plot = os.path.join(out_dir, f"{os.path.basename(args.preset)}.png")
    report_json = os.path.join(out_dir, "report.json")
    common = (["--config", args.config] if args.config else [])
    fast = ["--fast"] if args.fast else []
    print(f"demo: {args.preset}, {'fast' if args.fast else 'real time'}, bus {endpoint}, "
          f"output in {out_dir}", flush=True)
    signal.signal(signal.SIGTERM, _interrupt)
    with ProcessGroup(env, args.timeout) as group:
        with open(os.path.join(out_dir, "service.log"), "wb") as log:
            group.start("service", ["serve", *common, *fast], stdout=log, stderr=log)
            group.start("winder", ["winder", *common, *fast, "--jobs", "1", "--plot", plot,
                                   "--report-json", report_json])
            monitor_url = None
            if args.monitor:
                monitor_url = _start_monitor(group, common, args.monitor_port)
                if monitor_url is None:
                    return _fail(group, "the monitor did not start", out_dir)
                print(f"demo: monitor at {monitor_url} (open it in a browser)", flush=True)
            if not _wait_alive(args.config, group):
                return _fail(group, "the service or the winder did not come up", out_dir)
            publish = group.start("publisher", ["publish", args.preset, *common,
                                                "--wait-s", "30"])
            rc_pub = group.wait(publish)
            if rc_pub != 0:
                return _fail(group, f"the publisher failed (exit {rc_pub})", out_dir)
            rc_winder = group.wait(group.procs["winder"])
            if monitor_url and rc_winder is not None and os.path.exists(report_json):
                rc = _summarize(report_json, plot)
                _linger(monitor_url)
                return rc
        if rc_winder is None or not os.path.exists(report_json):
            return _fail(group, "the winder did not report", out_dir)
    return _summarize(report_json, plot)


def default_job(config: str | None, out_dir: str) -> str:
    """tube-1450 on the two-drive winder; on any other machine, a fiberpath-style program
    for its mandrel (radius from the C axis' path_scale) written to `out_dir`."""
    import os

    from lookahead.config import load_config_or_exit
    from lookahead_clients.cam_program import WindingProgram, gcode
    from lookahead_clients.fibre import radius_from_path_scale

    machine = load_config_or_exit(config).machine
    if tuple(machine.axes) == ("X", "C"):
        return "tube-1450"
    radius = (radius_from_path_scale(machine.path_scale[machine.axes.index("C")])
              if "C" in machine.axes else 100.0)
    path = os.path.join(out_dir, f"{machine.id}-circuit.gcode")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(gcode(WindingProgram(length=200.0, radius=radius, circuits=1, hoop=False,
                                      delivery="B" in machine.axes)))
    return path


def _wait_alive(config: str | None, group) -> bool:
    """Wait until NS/alive/planner and NS/alive/machine exist (or a subprocess died)."""
    import time

    from lookahead.bus import open_client_session
    from lookahead.config import load_config_or_exit
    from lookahead.protocol import key
    from lookahead_clients.busio import close_session, wait_for_token

    cfg = load_config_or_exit(config)
    session = open_client_session(cfg.zenoh)
    try:
        for who in ("planner", "machine"):
            while not wait_for_token(session, key(cfg.ns, "alive", who), 1.0):
                if group.any_exited() or group.expired():
                    return False
        time.sleep(0.3)  # the winder's setpoint subscription reaches the service
        return True
    finally:
        close_session(session)


def _start_monitor(group, common: list[str], port: int) -> str | None:
    """Start `lookahead monitor` in `group`; its address (the first line it prints), or
    None if it exited or the group's deadline passed first."""
    import select
    import subprocess

    proc = group.start("monitor", ["monitor", *common, "--port", str(port)],
                       stdout=subprocess.PIPE, text=True)
    while proc.poll() is None and not group.expired():
        if select.select([proc.stdout], [], [], 0.5)[0]:
            line = proc.stdout.readline()
            return line.split()[1] if line.startswith("monitor: http") else None
    return None


def _linger(url: str) -> None:
    """On a terminal, keep the monitor up (its page shows the winder's report) until Enter."""
    import contextlib

    if not sys.stdin.isatty():
        return
    with contextlib.suppress(EOFError):
        input(f"demo: the monitor stays at {url}; press Enter to stop it ")


def _fail(group, why: str, out_dir: str) -> int:
    print(f"demo: FAILED: {why}; logs in {out_dir}", file=sys.stderr)
    for name, rc in group.exit_codes().items():
        print(f"demo:   {name}: {'running' if rc is None else f'exit {rc}'}", file=sys.stderr)
    return 1


def _summarize(report_json: str, plot: str) -> int:
    import json
    import os

    with open(report_json, encoding="utf-8") as fh:
        report = json.load(fh)[-1]
    axes = report["axes"]
    print("\n=== winder report ===")
    print(f"winding time      {report['duration_s']:.3f} s")
    for kind, label in (("v", "velocity"), ("a", "acceleration"), ("j", "jerk")):
        peaks = "  ".join(f"{a} {100 * f:5.1f}%" for a, f in
                          zip(axes, report["peak_fraction"][kind], strict=True))
        print(f"peak {label:13s}{peaks}")
    print(f"violations        {report['violations']}  (gaps {report['gaps']}, "
          f"underruns {report['underruns']})")
    print(f"fibre angle error max {report['fibre_angle_error_max']:.4f} deg, mean "
          f"{report['fibre_angle_error_mean']:.4f} deg over {len(report['traverses'])} "
          "traverses")
    if report.get("fault"):
        print(f"fault             {report['fault']}")
    if os.path.exists(plot):
        print(f"plot              {plot}")
    print(f"result            {'CLEAN' if report['clean'] else 'NOT CLEAN'}")
    return 0 if report["clean"] else 1
