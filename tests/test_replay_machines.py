"""What replay promises (issue 12): bit-identical on the machine that made the recording,
within `FOREIGN_TOLERANCE` (or "diverged", exit 4) elsewhere. No bus: the fresh recordings
are made in-process by `record_engine`, on the machine running the test."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tomllib
from dataclasses import replace

import msgpack
import numpy as np
import pytest

from lookahead.config import build_config, default_config
from lookahead.protocol import SetpointBatch
from lookahead_clients.job_source import make_segments
from lookahead_clients.recording import (
    floating_point_environment,
    read_recording,
    software_versions,
)
from lookahead_clients.replay import (
    EXIT_DIVERGED,
    FOREIGN_TOLERANCE,
    default_tolerance,
    record_engine,
    replay,
)

GOLDEN = os.path.join(os.path.dirname(__file__), "data", "golden-short.rec")


def wavy_points(n: int = 400) -> np.ndarray:
    """A short winding-like stroke: X 0 -> 300 mm, C turning with a wobble (deg)."""
    t = np.linspace(0.0, 1.0, n)
    return np.column_stack([300.0 * t, 200.0 * t + 15.0 * np.sin(6.0 * np.pi * t)])


@pytest.fixture(scope="module", params=["heuristic", "lp"])
def fresh(request, tmp_path_factory):
    """(path, recording, config) of an in-process recording of `wavy_points`."""
    cfg = default_config()
    cfg = replace(cfg, planner=replace(cfg.planner, method=request.param))
    segs = make_segments(f"fresh-{request.param}", list(cfg.machine.axes), wavy_points(),
                         chunk=60)
    path = tmp_path_factory.mktemp("rec") / f"{request.param}.rec"
    with open(path, "wb") as fh:
        assert record_engine(cfg, segs, fh, feed_every=5) > 50
    return path, read_recording(str(path)), cfg


def replay_cli(path, *argv) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lookahead", "replay", str(path), *argv],
                          capture_output=True, text=True, timeout=300)


def planted(rec, delta: float):
    """`rec` with `delta` added to one position in the middle batch; returns its seq."""
    batches = list(rec.samples("setpoints"))
    victim = batches[len(batches) // 2]
    b = SetpointBatch.decode(victim["payload"])
    pos = np.array(b.pos)
    pos[3, 1] += delta
    victim["payload"] = SetpointBatch(b.job, b.seq, b.k0, b.dt, b.axes, pos, b.vel, b.acc,
                                      b.final, b.applied).encode()
    return b.seq, len(batches)


def rewrite(src, dst, header_change: dict) -> None:
    """Copy recording `src` to `dst` with `header_change` merged into its header."""
    with open(src, "rb") as fh:
        records = list(msgpack.Unpacker(fh, raw=False, strict_map_key=False))
    records[0] = {**records[0], **header_change}
    with open(dst, "wb") as fh:
        for r in records:
            fh.write(msgpack.packb(r, use_bin_type=True))


def test_a_recording_names_its_software_and_floating_point_environment(fresh):
    _, rec, _ = fresh
    assert rec.header["software"] == software_versions()
    fp = rec.header["fp_env"]
    assert fp == floating_point_environment()
    assert fp["cpu_model"] and fp["machine"] and fp["cpus"] >= 1
    assert default_tolerance(rec.header) == (0.0, "same machine")


def test_a_fresh_recording_replays_bit_identically_on_its_machine(fresh):
    path, rec, _ = fresh
    out = replay_cli(path)
    n = len(list(rec.samples("setpoints")))
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"{n} matched bit-identically, max |difference| 0" in out.stdout
    assert "0 limit violations" in out.stdout


def test_exact_mode_finds_a_1e12_change_in_a_fresh_recording(fresh, tmp_path):
    path, rec, cfg = fresh
    seq, n = planted(rec, 1e-12)
    res = replay(rec, cfg)  # tolerance 0
    assert res.batches == n and res.matched == n - 1
    assert 0 < res.max_diff < 1e-11 and f"/{seq} " in res.first_mismatch
    changed = tmp_path / "changed.rec"
    with open(path, "rb") as fh:
        records = list(msgpack.Unpacker(fh, raw=False, strict_map_key=False))
    with open(changed, "wb") as fh:  # the same change, through the command line
        for r in records:
            if r.get("type") == "sample" and r["key"].endswith("/setpoints"):
                b = SetpointBatch.decode(r["payload"])
                if b.seq == seq:
                    pos = np.array(b.pos)
                    pos[3, 1] += 1e-12
                    r = {**r, "payload": SetpointBatch(b.job, b.seq, b.k0, b.dt, b.axes, pos,
                                                       b.vel, b.acc, b.final,
                                                       b.applied).encode()}
            fh.write(msgpack.packb(r, use_bin_type=True))
    out = replay_cli(changed)
    assert out.returncode == 1, out.stdout + out.stderr
    assert f"{n - 1} matched bit-identically" in out.stdout


def test_a_recording_from_another_cpu_is_compared_within_the_tolerance(fresh, tmp_path):
    path, rec, _ = fresh
    other = tmp_path / "other-cpu.rec"
    fp = {**rec.header["fp_env"], "cpu_model": "SomeVendor / Other CPU / 1 / 2 / 3"}
    rewrite(path, other, {"fp_env": fp})
    out = replay_cli(other)
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"within {FOREIGN_TOLERANCE:g}: different CPU" in out.stdout
    assert "cpu_model SomeVendor / Other CPU" in out.stdout  # it says what differs


@pytest.mark.parametrize("fresh", ["lp"], indirect=True)
def test_last_bit_differences_of_the_lp_stay_within_the_foreign_tolerance(fresh):
    """The tolerance's derivation (bench/replay_tolerance.py), as a property: every input
    coordinate moved by one ulp moves the LP's setpoints by far less than the tolerance (the
    heuristic's decisions can flip at one ulp: the bench counts those runs)."""
    _, rec, cfg = fresh
    for seed in (0, 1):
        res = replay(rec, cfg, tolerance=FOREIGN_TOLERANCE, perturb=2.0 ** -52, seed=seed)
        assert res.identical, res.first_mismatch
        assert 0 < res.max_diff < FOREIGN_TOLERANCE / 10


def test_the_golden_recording_replays_on_any_machine():
    """Bit-identically where it was recorded (its header names the machine), else within
    the cross-machine tolerance, or "diverged" (exit 4) where a planning decision flips;
    never over a limit. Re-record it (README, "replay") when a planner changes on purpose."""
    out = replay_cli(GOLDEN)
    assert "0 limit violations" in out.stdout, out.stdout + out.stderr
    assert "batches of 1 job(s) (6 segments, 0 commands)" in out.stdout
    here, _ = default_tolerance(read_recording(GOLDEN).header)
    if here == 0.0:
        assert out.returncode == 0, out.stdout + out.stderr
        assert "136 matched bit-identically" in out.stdout
    elif out.returncode == 0:
        assert f"136 matched within {FOREIGN_TOLERANCE:g}" in out.stdout
    else:
        assert out.returncode == EXIT_DIVERGED and "diverged" in out.stdout, out.stdout


def test_the_golden_recording_from_another_cpu_is_compared_within_the_tolerance(tmp_path):
    other = tmp_path / "golden-other-cpu.rec"
    header = read_recording(GOLDEN).header
    rewrite(GOLDEN, other, {"fp_env": {**header["fp_env"], "cpu_model": "Other / CPU"}})
    out = replay_cli(other)
    assert out.returncode in (0, EXIT_DIVERGED), out.stdout + out.stderr
    assert "different CPU" in out.stdout and "0 limit violations" in out.stdout


def test_replay_finds_a_change_larger_than_the_tolerance_in_the_golden_file():
    rec = read_recording(GOLDEN)
    cfg = build_config(tomllib.loads(rec.header["config_toml"]))
    if not replay(rec, cfg, tolerance=FOREIGN_TOLERANCE).identical:
        pytest.skip("the golden recording diverges on this CPU (a planning decision flips)")
    seq, n = planted(rec, 10 * FOREIGN_TOLERANCE)
    res = replay(rec, cfg, tolerance=FOREIGN_TOLERANCE)
    assert res.batches == n and res.matched == n - 1
    assert f"/{seq} " in res.first_mismatch
    assert res.max_diff >= 9 * FOREIGN_TOLERANCE


def test_record_engine_writes_what_read_recording_reads():
    cfg = default_config()
    segs = make_segments("tiny", list(cfg.machine.axes), wavy_points(40), chunk=10)
    buf = io.BytesIO()
    n = record_engine(cfg, segs, buf)
    records = list(msgpack.Unpacker(io.BytesIO(buf.getvalue()), raw=False))
    keys = [r["key"].rsplit("/", 1)[1] for r in records if r.get("type") == "sample"]
    assert keys.count("segments") == len(segs) and keys.count("setpoints") == n
    finals = [SetpointBatch.decode(r["payload"]).final for r in records
              if r.get("type") == "sample" and r["key"].endswith("/setpoints")]
    assert finals[-1] and not any(finals[:-1])
