"""Configuration: defaults, round trip through TOML, and one named error per kind of mistake."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from lookahead.cli import main
from lookahead.config import (
    ConfigError,
    build_config,
    config_to_toml,
    default_config,
    endpoint_problem,
    load_config,
)


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "machine.toml"
    path.write_text(text)
    return path


def errors_of(tmp_path: Path, text: str) -> list[str]:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(path, environ={})
    for line in info.value.errors:
        assert line.startswith(f"{path}: ")
    return info.value.errors


def test_defaults_are_the_winder_demo() -> None:
    cfg = default_config()
    assert cfg.ns == "lookahead/winder"
    assert cfg.machine.axes == ("X", "C")
    assert cfg.machine.limits.vmax.tolist() == [500.0, 720.0]
    assert math.isclose(cfg.machine.path_scale[1], math.pi / 180 * 100)
    assert cfg.zenoh.listen == ("tcp/127.0.0.1:7447",)


def test_show_output_loads_back_identically(tmp_path: Path) -> None:
    cfg = default_config()
    path = write(tmp_path, config_to_toml(cfg))
    assert load_config(path, environ={}) == cfg


def test_config_is_immutable() -> None:
    cfg = default_config()
    with pytest.raises(AttributeError):
        cfg.machine.id = "other"  # type: ignore[misc]


@pytest.mark.parametrize(
    ("text", "key", "words"),
    [
        ("[machine]\nspeed = 3\n", "machine.speed", "unknown key"),
        ("[bogus]\nx = 1\n", "bogus", "unknown section"),
        ("[machine]\nvmax = [500.0]\n", "machine.vmax", "one entry per axis"),
        ("[machine]\npath_scale = [1.0, 2.0, 3.0]\n", "machine.path_scale", "one entry per axis"),
        ("[machine]\namax = [2000.0, -1.0]\n", "machine.amax", "finite and > 0"),
        ("[machine]\njmax = [0.0, 1.0]\n", "machine.jmax", "finite and > 0"),
        ("[machine]\nvmax = [inf, 1.0]\n", "machine.vmax", "finite and > 0"),
        ("[machine]\nvmax = [nan, 1.0]\n", "machine.vmax", "finite and > 0"),
        ("[machine]\ndt = 0.0\n", "machine.dt", "> 0"),
        ("[machine]\nvmax = \"fast\"\n", "machine.vmax", "expected an array"),
        ("[machine]\nid = \"a b\"\n", "machine.id", "A-Za-z0-9_.-"),
        ("[planner]\nmethod = \"magic\"\n", "planner.method", "unknown planner method"),
        ("[zenoh]\nlisten = [\"127.0.0.1:7447\"]\n", "zenoh.listen[0]", "malformed endpoint"),
        ("[zenoh]\nconnect = [\"tcp/host\"]\n", "zenoh.connect[0]", "HOST:PORT"),
        ("[zenoh]\nconnect = [\"tcp/host:99999\"]\n", "zenoh.connect[0]", "not in 0..65535"),
        ("[zenoh]\nmode = \"router\"\nconnect = []\nlisten = []\n[service]\nbatch = 0\n",
         "service.batch", ">= 1"),
        ("[zenoh]\nmode = \"client\"\n", "zenoh.connect", "client mode"),
        ("[zenoh]\nmode = \"satellite\"\n", "zenoh.mode", "unknown zenoh mode"),
    ],
)
def test_each_error_names_file_key_and_problem(tmp_path: Path, text: str, key: str,
                                               words: str) -> None:
    errors = errors_of(tmp_path, text)
    assert any(f": {key}: " in e and words in e for e in errors), errors


def test_all_errors_are_collected(tmp_path: Path) -> None:
    errors = errors_of(tmp_path, "[machine]\nvmax = [1.0]\n[planner]\nmethod = \"x\"\n")
    assert len(errors) == 2


def test_invalid_toml_names_the_file(tmp_path: Path) -> None:
    errors = errors_of(tmp_path, "[machine\n")
    assert "not valid TOML" in errors[0]


def test_environment_overrides() -> None:
    cfg = build_config({}, environ={"LOOKAHEAD_ZENOH_CONNECT": "tcp/router:7447,tcp/b:1",
                                    "LOOKAHEAD_ZENOH_MODE": "client",
                                    "LOOKAHEAD_MACHINE_ID": "winder-2",
                                    "LOOKAHEAD_SERVICE_BATCH": "20"})
    assert cfg.zenoh.connect == ("tcp/router:7447", "tcp/b:1")
    assert cfg.zenoh.mode == "client"
    assert cfg.ns == "lookahead/winder-2"
    assert cfg.service.batch == 20
    with pytest.raises(ConfigError, match=r"service\.batch: expected an integer"):
        build_config({}, environ={"LOOKAHEAD_SERVICE_BATCH": "many"})


@pytest.mark.parametrize("ep", ["tcp/127.0.0.1:7447", "udp/[::1]:7447", "tls/router:443",
                                "unixsock-stream//tmp/z.sock"])
def test_good_endpoints(ep: str) -> None:
    assert endpoint_problem(ep) is None


def test_cli_check_exit_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = write(tmp_path, config_to_toml(default_config()))
    assert main(["config", "check", str(good)]) == 0
    assert "OK" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text("[planner]\nmethod = \"magic\"\n")
    assert main(["config", "check", str(bad)]) == 2
    assert "planner.method" in capsys.readouterr().err
    assert main(["config", "check", str(tmp_path / "missing.toml")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_bus_options_become_config_overrides(monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    for var in ("LOOKAHEAD_MACHINE_ID", "LOOKAHEAD_ZENOH_MODE", "LOOKAHEAD_ZENOH_CONNECT",
                "LOOKAHEAD_ZENOH_LISTEN", "LOOKAHEAD_ZENOH_CONFIG_FILE"):
        monkeypatch.setenv(var, "")  # records the original, so the test's changes are undone
        monkeypatch.delenv(var)
    assert main(["config", "show"]) == 0
    capsys.readouterr()
    code = main(["config", "--machine-id", "w7", "--zenoh-mode", "client",
                 "--connect", "tcp/router:7447", "--connect", "tcp/backup:7447",
                 "--listen", "", "show"])
    assert code == 0
    cfg = load_config(None)
    assert cfg.ns == "lookahead/w7"
    assert cfg.zenoh.mode == "client"
    assert cfg.zenoh.connect == ("tcp/router:7447", "tcp/backup:7447")
    assert cfg.zenoh.listen == ()
    assert os.environ["LOOKAHEAD_ZENOH_CONNECT"] == "tcp/router:7447,tcp/backup:7447"
