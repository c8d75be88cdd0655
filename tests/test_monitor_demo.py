"""`lookahead demo --monitor`: the monitor starts beside the real-time run, the demo prints
its address, and the page's endpoints follow the demo's job while it runs."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time

import pytest

from lookahead.bus import free_tcp_endpoint
from test_monitor_bus import get

pytestmark = [pytest.mark.bus, pytest.mark.filterwarnings("ignore::ResourceWarning")]


def test_demo_prints_the_monitor_address_and_the_monitor_follows_the_run(tmp_path):
    env = {**os.environ, "LOOKAHEAD_ZENOH_LISTEN": free_tcp_endpoint(),
           "LOOKAHEAD_PLANNER_METHOD": "heuristic", "PYTHONUNBUFFERED": "1"}
    env.pop("LOOKAHEAD_ZENOH_CONNECT", None)
    demo = subprocess.Popen([sys.executable, "-m", "lookahead", "demo", "--monitor",
                             "--monitor-port", "0", "--out-dir", str(tmp_path),
                             "--timeout", "120"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    try:
        url, lines = None, []
        deadline = time.monotonic() + 60
        while url is None:
            assert time.monotonic() < deadline and demo.poll() is None, lines
            if select.select([demo.stdout], [], [], 0.5)[0]:
                lines.append(demo.stdout.readline())
                if lines[-1].startswith("demo: monitor at http://"):
                    url = lines[-1].split()[3]
        seen = None
        while seen is None:  # the real-time job lasts ~9 s: the monitor sees it under way
            assert time.monotonic() < deadline, lines
            state = get(url, "/api/state")
            if state["job"] and state["rows"] and state["progress"]["fraction"] is not None:
                seen = state
            time.sleep(0.2)
        out, err = demo.communicate(timeout=120)
    finally:
        if demo.poll() is None:
            demo.kill()
            demo.communicate()
    # the run went to the end and its limits held; whether it was CLEAN also depends on
    # underruns, i.e. on how loaded this machine's cores are (not asserted here)
    assert demo.returncode in (0, 1), out + err
    assert "=== winder report ===" in out and "violations        0  (gaps 0," in out, out
    assert seen["ns"] == "lookahead/winder" and seen["service"] == "up"
    assert seen["path"]["complete"] and 0 <= seen["progress"]["fraction"] < 1
