"""Deployment without Docker: a router, two machines, the compose file, access control.

The plant of docker/compose.yaml is rebuilt here from processes: a Python zenoh session in
router mode, and per machine id one planner and one winder in client mode, configured only
through the LOOKAHEAD_* environment variables the compose file uses.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from lookahead.bus import free_tcp_endpoint
from lookahead.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"

#: The environment keys that place a process on the plant; compose uses exactly these.
PLANT_ENV_KEYS = {"LOOKAHEAD_MACHINE_ID", "LOOKAHEAD_ZENOH_MODE", "LOOKAHEAD_ZENOH_CONNECT",
                  "LOOKAHEAD_ZENOH_LISTEN"}


def plant_env(machine_id: str, router: str) -> dict[str, str]:
    """Environment of a planner/winder/publisher of `machine_id` on the router `router`."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("LOOKAHEAD_")}
    env.update({"LOOKAHEAD_MACHINE_ID": machine_id, "LOOKAHEAD_ZENOH_MODE": "client",
                "LOOKAHEAD_ZENOH_CONNECT": router, "LOOKAHEAD_ZENOH_LISTEN": ""})
    return env


def lookahead(*args: str, env: dict[str, str], log: Path) -> subprocess.Popen:
    out = log.open("w")
    return subprocess.Popen([sys.executable, "-m", "lookahead", *args], env=env,
                            stdout=out, stderr=subprocess.STDOUT)


def router_session(endpoint: str, text: str | None = None):
    import zenoh

    if text is None:
        conf = zenoh.Config()
        conf.insert_json5("mode", '"router"')
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    else:
        conf = zenoh.Config.from_json5(text)
    return zenoh.open(conf)


def client_session(endpoint: str, user: str | None = None, password: str | None = None):
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    if user is not None:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return zenoh.open(conf)


def stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()


@pytest.mark.bus
def test_two_machines_on_one_router_get_only_their_own_setpoints(tmp_path: Path) -> None:
    import zenoh

    router_ep = free_tcp_endpoint()
    router = router_session(router_ep)
    spy = client_session(router_ep)
    seen: dict[str, set[str]] = {}

    def on_setpoints(sample: zenoh.Sample) -> None:
        job = sample.payload.to_bytes()
        from lookahead.protocol import SetpointBatch

        seen.setdefault(str(sample.key_expr), set()).add(SetpointBatch.decode(job).job)

    sub = spy.declare_subscriber("lookahead/*/setpoints", on_setpoints)
    procs: list[subprocess.Popen] = []
    machines = ("plant-a", "plant-b")
    try:
        for m in machines:
            env = plant_env(m, router_ep)
            procs.append(lookahead("serve", "--fast", "--method", "heuristic",
                                   env=env, log=tmp_path / f"serve-{m}.log"))
            procs.append(lookahead("winder", "--fast", "--jobs", "1", "--report-json",
                                   str(tmp_path / f"report-{m}.json"),
                                   env=env, log=tmp_path / f"winder-{m}.log"))
        publishers = [lookahead("publish", "tube-1450", "--job", f"job-{m}", "--chunk", "400",
                                "--quiet", "--timeout", "120", env=plant_env(m, router_ep),
                                log=tmp_path / f"publish-{m}.log") for m in machines]
        procs += publishers
        for m, pub in zip(machines, publishers, strict=True):
            assert pub.wait(timeout=150) == 0, (tmp_path / f"publish-{m}.log").read_text()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not all(
                (tmp_path / f"report-{m}.json").exists() for m in machines):
            time.sleep(0.2)
        for m in machines:
            reports = json.loads((tmp_path / f"report-{m}.json").read_text())
            assert [r["job"] for r in reports] == [f"job-{m}"]
            assert reports[0]["clean"], reports[0]
            assert reports[0]["violations"] == 0
        assert seen == {f"lookahead/{m}/setpoints": {f"job-{m}"} for m in machines}
    finally:
        stop(procs)
        sub.undeclare()
        spy.close()
        router.close()


def compose() -> dict:
    return yaml.safe_load((DOCKER / "compose.yaml").read_text())


def test_compose_commands_are_valid_cli_invocations() -> None:
    services = compose()["services"]
    parser = build_parser()
    ours = {name: svc for name, svc in services.items() if "build" in svc}
    assert {"planner-1", "winder-1", "planner-2", "winder-2", "publisher-1"} <= set(ours)
    ids = set()
    for name, svc in ours.items():
        args = parser.parse_args(svc["command"])  # SystemExit on an invalid invocation
        assert args.command in ("serve", "winder", "publish"), name
        env = svc["environment"]
        assert set(env) == PLANT_ENV_KEYS, name
        assert env["LOOKAHEAD_ZENOH_MODE"] == "client"
        assert env["LOOKAHEAD_ZENOH_CONNECT"] == "tcp/router:7447"
        assert env["LOOKAHEAD_ZENOH_LISTEN"] == ""
        ids.add(env["LOOKAHEAD_MACHINE_ID"])
    # one planner and one winder per machine id
    for machine_id in ids:
        kinds = sorted(parser.parse_args(s["command"]).command for s in ours.values()
                       if s["environment"]["LOOKAHEAD_MACHINE_ID"] == machine_id)
        assert kinds.count("serve") == 1 and kinds.count("winder") == 1, (machine_id, kinds)


def test_compose_router_matches_the_python_binding() -> None:
    from importlib.metadata import version

    image = compose()["services"]["router"]["image"]
    name, tag = image.split(":")
    assert name == "eclipse/zenoh"
    assert tag.split(".")[:2] == version("eclipse-zenoh").split(".")[:2]


def test_plant_env_is_a_valid_configuration() -> None:
    from lookahead.config import load_config

    cfg = load_config(DOCKER / "machine.toml",
                      environ=plant_env("winder-7", "tcp/router:7447"))
    assert cfg.ns == "lookahead/winder-7"
    assert cfg.zenoh.mode == "client" and cfg.zenoh.listen == ()
    assert cfg.zenoh.connect == ("tcp/router:7447",)


@pytest.mark.bus
def test_access_control_only_the_planner_puts_setpoints(tmp_path: Path) -> None:
    endpoint = free_tcp_endpoint()
    creds = tmp_path / "credentials.txt"
    creds.write_text((DOCKER / "credentials.txt").read_text())
    text = (DOCKER / "router-acl.json5").read_text()
    text = text.replace("tcp/0.0.0.0:7447", endpoint).replace("/config/credentials.txt",
                                                              str(creds))
    users = dict(line.split(":", 1) for line in creds.read_text().split())
    router = router_session(endpoint, text)
    winder = client_session(endpoint, "winder", users["winder"])
    planner = client_session(endpoint, "planner", users["planner"])
    intruder = client_session(endpoint, "publisher", users["publisher"])
    import zenoh

    got: list[tuple[str, bytes]] = []
    sub = winder.declare_subscriber("lookahead/w/**", zenoh.handlers.FifoChannel(64))
    try:
        probe = intruder.declare_publisher("lookahead/w/segments")
        deadline = time.monotonic() + 10
        while not probe.matching_status.matching:  # the winder's subscription reached it
            assert time.monotonic() < deadline, "the winder's subscription never arrived"
            time.sleep(0.02)
        probe.undeclare()
        planner.put("lookahead/w/setpoints", b"planner")
        intruder.put("lookahead/w/setpoints", b"intruder")
        intruder.put("lookahead/w/segments", b"segments")
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and len(got) < 2:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.02)
                continue
            got.append((str(sample.key_expr), sample.payload.to_bytes()))
        time.sleep(0.3)
        while (sample := sub.try_recv()) is not None:
            got.append((str(sample.key_expr), sample.payload.to_bytes()))
        assert sorted(got) == [("lookahead/w/segments", b"segments"),
                               ("lookahead/w/setpoints", b"planner")]
        with pytest.raises(Exception, match="Unable to connect"):
            client_session(endpoint, "planner", "wrong-password")
    finally:
        sub.undeclare()
        for s in (winder, planner, intruder, router):
            s.close()
