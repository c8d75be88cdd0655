"""`lookahead demo --fast` end to end (the README's main command), and its helpers."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

from lookahead.bus import free_tcp_endpoint
from lookahead_clients.demo import _port_free, pick_endpoint


def test_port_probe_sees_a_busy_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        busy = f"tcp/127.0.0.1:{sock.getsockname()[1]}"
        assert not _port_free(busy)
    assert _port_free(free_tcp_endpoint())
    assert pick_endpoint().startswith("tcp/127.0.0.1:")


def test_demo_fast_runs_clean(tmp_path):
    env = {**os.environ, "LOOKAHEAD_ZENOH_LISTEN": free_tcp_endpoint()}
    for var in ("LOOKAHEAD_PLANNER_METHOD", "LOOKAHEAD_ZENOH_CONNECT"):
        env.pop(var, None)  # the demo as a user runs it: default configuration
    out = subprocess.run([sys.executable, "-m", "lookahead", "demo", "--fast", "--out-dir",
                          str(tmp_path), "--timeout", "170"], env=env, capture_output=True,
                         text=True, timeout=200)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "result            CLEAN" in out.stdout
    plot = tmp_path / "tube-1450.png"
    assert f"plot              {plot}" in out.stdout
    assert plot.stat().st_size > 10_000
    (report,) = json.loads((tmp_path / "report.json").read_text())
    assert report["clean"] and report["violations"] == 0
    assert f"winding time      {report['duration_s']:.3f} s" in out.stdout
    # nothing the demo started is left behind: its service log ends with the stop line
    assert "stopped:" in (tmp_path / "service.log").read_text()


def test_demo_failure_stops_everything(tmp_path):
    env = {**os.environ, "LOOKAHEAD_ZENOH_LISTEN": free_tcp_endpoint()}
    env.pop("LOOKAHEAD_ZENOH_CONNECT", None)
    out = subprocess.run([sys.executable, "-m", "lookahead", "demo", "--fast", "--preset",
                          "no-such-preset", "--out-dir", str(tmp_path), "--timeout", "60"],
                         env=env, capture_output=True, text=True, timeout=90)
    assert out.returncode == 1
    assert "the publisher failed (exit 2)" in out.stderr
    assert "neither a preset" in out.stderr  # the publisher's own reason, passed through
    # the service was stopped by the demo (SIGTERM -> its orderly stop), not left running
    assert "stopped:" in (tmp_path / "service.log").read_text()
