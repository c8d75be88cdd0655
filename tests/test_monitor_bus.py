"""`lookahead monitor` against the real service on a loopback bus (subprocesses on a free
port, as in test_clients_bus.py): a job's status, setpoints and path reach the monitor's
endpoints, progress goes 0 -> 100 %, commands from the page's endpoint hold the machine or
come back refused with the reason, a machine id without a service says so, and SSE clients
that go away cost nothing."""

from __future__ import annotations

import itertools
import json
import select
import socket
import subprocess
import time
import urllib.request
from urllib.parse import urlparse

import pytest

from test_clients_bus import bus_env, lookahead, stop, wait_alive, wait_subscribed

pytestmark = [pytest.mark.bus, pytest.mark.filterwarnings("ignore::ResourceWarning")]


def start_monitor(env, *argv: str, timeout: float = 40.0) -> tuple[subprocess.Popen, str]:
    """`lookahead monitor --port 0 ...`; returns the process and the page's address (the
    first line it prints)."""
    proc = lookahead(env, "monitor", "--port", "0", *argv)
    deadline = time.monotonic() + timeout
    line = ""
    while time.monotonic() < deadline and proc.poll() is None:
        ready, _, _ = select.select([proc.stdout], [], [], 0.5)
        if ready:
            line = proc.stdout.readline()
            break
    assert line.startswith("monitor: http://"), (line, proc.poll())
    return proc, line.split()[1]


def get(url: str, path: str) -> dict:
    with urllib.request.urlopen(url + path.lstrip("/"), timeout=20) as resp:
        return json.loads(resp.read())


def post(url: str, path: str, body: dict | None = None) -> dict:
    req = urllib.request.Request(url + path.lstrip("/"), data=json.dumps(body or {}).encode(),
                                 method="POST", headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as resp:
        return json.loads(resp.read())


def poll(url: str, machine: str, until, timeout: float = 30.0, what: str = "") -> dict:
    """The first state of `machine` for which `until(state)` holds (polled every 50 ms)."""
    deadline = time.monotonic() + timeout
    while True:
        state = get(url, f"/api/state?machine={machine}")
        if until(state):
            return state
        assert time.monotonic() < deadline, f"timed out waiting for {what}: {state['status']}"
        time.sleep(0.05)


def state_is(name: str):
    return lambda s: s["status"] is not None and s["status"]["state"] == name


def test_monitor_follows_a_real_time_job_and_its_commands(tmp_path):
    env = bus_env("heuristic")
    report_json = tmp_path / "report.json"
    service = lookahead(env, "serve", "--log-level", "WARNING")  # real time: the job lasts
    winder = lookahead(env, "winder", "--jobs", "1", "--report-json", str(report_json))
    procs = [service, winder]
    try:
        monitor, url = start_monitor(env, "--machine-id", "winder", "--machine-id", "nobody")
        procs.append(monitor)
        wait_alive(env, "planner", "machine")
        wait_subscribed(env, "setpoints")
        machines = get(url, "/api/machines")
        assert [m["ns"] for m in machines] == ["lookahead/winder", "lookahead/nobody"]
        assert machines[0]["axes"] == ["X", "C"] and machines[0]["vmax"] == [500.0, 720.0]
        poll(url, "winder", lambda s: s["service"] == "up" and s["status"] is not None,
             what="the service's status")
        # no service on that id: said so (liveliness NS/alive/planner), commands time out
        nobody = poll(url, "nobody", lambda s: s["service"] != "checking", what="liveliness")
        assert nobody["service"] == "none" and nobody["status"] is None
        pub = lookahead(env, "publish", "tube-1450", "--job", "watched", "--quiet",
                        "--timeout", "120")
        procs.append(pub)
        first = poll(url, "winder", lambda s: s["job"] == "watched" and s["rows"]
                     and s["progress"]["fraction"] is not None, what="the job's setpoints")
        assert first["path"]["complete"] and first["path"]["segments"] == 6
        assert first["path"]["points"][0] == [0.0, 0.0]  # tube-1450 starts at the origin
        assert first["progress"]["fraction"] < 0.5
        fractions = [first["progress"]["fraction"]]
        # refused: by the monitor (a value the protocol refuses) and by the service
        bad = post(url, "/api/cmd/winder/override", {"value": 2.0})
        assert not bad["ok"] and bad["by"] == "monitor" and "override" in bad["error"]
        refused = post(url, "/api/cmd/winder/resume")
        assert not refused["ok"] and refused["by"] == "service"
        assert "not holding" in refused["error"]
        assert post(url, "/api/cmd/winder/hold") == {"ok": True, "error": None, "by": "service"}
        held = poll(url, "winder", state_is("holding"), what="holding")
        fractions.append(held["progress"]["fraction"])
        assert fractions[-1] < 1.0
        assert post(url, "/api/cmd/winder/resume")["ok"]
        poll(url, "winder", state_is("running"), what="running again")
        none = post(url, "/api/cmd/nobody/hold")
        assert not none["ok"] and "no service answered" in none["error"]
        done = None
        deadline = time.monotonic() + 60
        left = []  # (elapsed, time left) the page shows once the plan reaches the end
        while done is None:
            s = get(url, "/api/state?machine=winder")
            if s["progress"]["fraction"] is not None and s["job"] == "watched":
                fractions.append(s["progress"]["fraction"])
            if s["progress"]["remaining_s"] is not None and s["job"] == "watched":
                left.append((s["progress"]["elapsed_s"], s["progress"]["remaining_s"]))
            if s["report"] is not None and s["progress"]["duration_s"] is not None:
                done = s
            assert time.monotonic() < deadline, s["status"]
            time.sleep(0.1)
        assert pub.wait(timeout=30) == 0
    finally:
        stop(*procs)
    # progress goes 0 -> 100 % along the path, never backwards
    assert all(b >= a - 1e-9 for a, b in itertools.pairwise(fractions))
    assert fractions[-1] == pytest.approx(1.0, abs=1e-6)
    types = [e["type"] for e in done["events"]]
    assert types[0] == "job_started" and types[-1] == "job_finished"
    # the monitor's finite differences are the checker's: the same peaks as the winder's
    (report,) = json.loads(report_json.read_text())
    assert done["report"]["job"] == report["job"] == "watched"
    assert done["gaps"] == 0 and done["samples"] == report["samples"]
    assert done["progress"]["duration_s"] == pytest.approx(report["duration_s"], abs=0.002)
    # the time left shown after the resume (no command since): exact, from the plan
    assert len(left) >= 3, left
    dt = machines[0]["dt"]
    for elapsed, remaining in left:
        assert elapsed + remaining == pytest.approx(done["progress"]["duration_s"], abs=dt)
    assert all(b[1] <= a[1] for a, b in itertools.pairwise(left))
    for kind in ("v", "a", "j"):
        assert done["peak"][kind] == pytest.approx(report["peak_fraction"][kind], rel=1e-9)
    commands = [(c["verb"], c["ok"]) for c in done["commands"]]
    assert ("hold", True) in commands and ("resume", False) in commands


def open_sse(url: str) -> tuple[socket.socket, bytes]:
    """A browser-less SSE client: the raw request, read until the first update arrived;
    returns the socket and what it read."""
    u = urlparse(url)
    sock = socket.create_connection((u.hostname, u.port), timeout=20)
    sock.sendall(b"GET /api/stream HTTP/1.1\r\nHost: x\r\nAccept: text/event-stream\r\n\r\n")
    data = b""
    while b"event: update" not in data:
        chunk = sock.recv(65536)
        assert chunk, "the stream closed"
        data += chunk
    return sock, data


def test_sse_clients_that_go_away_cost_the_service_nothing(tmp_path):
    env = bus_env("heuristic")
    report_json = tmp_path / "report.json"
    service = lookahead(env, "serve", "--fast", "--log-level", "WARNING")
    winder = lookahead(env, "winder", "--fast", "--jobs", "1", "--report-json",
                       str(report_json))
    procs = [service, winder]
    try:
        monitor, url = start_monitor(env)
        procs.append(monitor)
        wait_alive(env, "planner", "machine")
        wait_subscribed(env, "setpoints")
        poll(url, "winder", lambda s: s["service"] == "up", what="the service")
        # clients that read one update and vanish: closed, reset, or left open unread
        for i in range(4):
            sock, _ = open_sse(url)
            if i % 2:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\0\0\0\0\0\0\0")
            sock.close()
        stalled, _ = open_sse(url)  # never reads again during the job
        pub = subprocess.run([*lookahead_argv(), "publish", "tube-1450", "--job", "fastjob",
                              "--timeout", "60"], env=env, capture_output=True, text=True,
                             timeout=90)
        assert pub.returncode == 0, pub.stderr
        winder.wait(timeout=30)
        done = poll(url, "winder", lambda s: s["report"] is not None, what="the report")
        stalled.close()
        health = poll_health(url, lambda h: h["sse_clients"] == 0)
        assert health["sse_served"] == 5
        # a new client still gets the whole picture
        sock, data = open_sse(url)
        while data.count(b"event: update") < 2:
            data += sock.recv(1 << 20)
        sock.close()
    finally:
        stop(*procs)
    assert done["progress"]["fraction"] == pytest.approx(1.0, abs=1e-6)
    assert done["gaps"] == 0 and done["report"]["job"] == "fastjob"
    assert done["report"]["violations"] == 0 and done["report"]["gaps"] == 0
    first_update = data.split(b"event: update\ndata: ", 1)[1].split(b"\n\n", 1)[0]
    (snap,) = json.loads(first_update)
    assert snap["job"] == "fastjob" and snap["rows"] and snap["path"]["complete"]


def lookahead_argv() -> list[str]:
    import sys

    return [sys.executable, "-m", "lookahead"]


def poll_health(url: str, until, timeout: float = 30.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        health = get(url, "/api/health")
        if until(health):
            return health
        assert time.monotonic() < deadline, health
        time.sleep(0.1)
