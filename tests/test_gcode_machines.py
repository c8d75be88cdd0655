"""Real winder programs (issue 17): G-code letters from the machine configuration, dropped
letters, dialects and what F caps, machines of 3 and 4 drives, large mandrel angles."""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lookahead import plan_cli
from lookahead.checker import LimitChecker
from lookahead.config import ConfigError, build_config, load_config, machine_names
from lookahead.geometry.gcode import read_gcode
from lookahead.geometry.spline_path import fit_points
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.sampling import sample_profile, sample_times
from lookahead.stream.planners import make_planner
from lookahead_clients.cam_program import WindingProgram, gcode

EPS = float(np.finfo(float).eps)


def config_errors(raw: dict) -> list[str]:
    with pytest.raises(ConfigError) as info:
        build_config(raw, "m.toml")
    return info.value.errors


def three_axes(**machine) -> dict:
    return {"axes": ["X", "C", "B"], "units": ["mm", "deg", "deg"], "vmax": [500, 720, 360],
            "amax": [2000, 3000, 3000], "jmax": [20000, 30000, 30000],
            "path_scale": [1.0, 1.745, 0.1], **machine}


@pytest.mark.parametrize(("gcode_table", "expected"), [
    ({"letters": ["X:X", "Q:C", "B:B"]}, "gcode.letters[1]: 'Q' is not a G-code axis letter"),
    ({"letters": ["X:X", "A:C", "B:C"]}, "gcode.letters[2]: two letters on axis C (A and B)"),
    ({"letters": ["X:X", "A:C"]}, "gcode.letters: no letter drives axis B"),
    ({"letters": ["X:X", "A:C", "B:Z"]}, "gcode.letters[2]: B -> Z, but the machine has no "
                                         "axis Z"),
    ({"letters": ["X:X", "A:C", "B:B", "A:X"]}, "letter A is mapped twice"),
    ({"letters": ["X:X", "A:C", "B:B"], "ignore": ["B"]}, "gcode.ignore[0]: letter B is "
                                                          "mapped to an axis"),
    ({"dialect": "fanuc"}, "gcode.dialect: unknown dialect 'fanuc'"),
    ({"letters": ["XX"]}, 'gcode.letters[0]: expected "LETTER:AXIS"'),
])
def test_config_check_names_each_letter_problem(gcode_table, expected):
    errors = config_errors({"machine": three_axes(), "gcode": gcode_table})
    assert any(e.startswith("m.toml: ") and expected in e for e in errors), errors


def test_without_letters_each_axis_named_by_a_letter_gets_it():
    assert build_config({}).gcode_letters == {"X": "X", "A": "C"}  # the winder: A is C
    xy = build_config({"machine": {"axes": ["X", "Y"], "units": ["mm", "mm"],
                                   "vmax": [1, 1], "amax": [1, 1], "jmax": [1, 1],
                                   "path_scale": [1, 1]}})
    assert xy.gcode_letters == {"X": "X", "Y": "Y"}
    assert build_config({"machine": three_axes()}).gcode_letters == {"X": "X", "A": "C",
                                                                      "B": "B"}


def test_shipped_machines_load_and_check():
    assert {"winder2", "winder3", "winder4"} <= set(machine_names())
    w3, w4 = load_config("winder3"), load_config("winder4")
    assert w3.machine.axes == ("X", "C", "B") and w3.gcode_letters["B"] == "B"
    assert w4.machine.axes == ("X", "Y", "C", "B") and w4.gcode_letters["Y"] == "Y"
    assert load_config("winder2").machine == build_config({}).machine
    out = subprocess.run([sys.executable, "-m", "lookahead", "config", "check", "winder3"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and 'letters = ["X:X", "A:C", "B:B"]' in out.stdout


PROGRAM = WindingProgram(length=120.0, radius=100.0, circuits=1, hoop=True, band=30.0)


def parse(argv):
    parser = argparse.ArgumentParser()
    plan_cli.add_parser(parser.add_subparsers())
    return parser.parse_args(["plan", *argv])


def test_a_letter_the_machine_lacks_is_refused_in_one_line(tmp_path, capsys):
    job = tmp_path / "job.gcode"
    job.write_text(gcode(PROGRAM))
    assert plan_cli.run(parse([str(job), "--method", "heuristic"])) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "line 6: letter B (B0): this machine has no axis for it" in err
    assert "gcode.letters" in err and "--ignore-letters B" in err


def test_ignored_letters_are_dropped_with_a_warning(tmp_path, capsys):
    job = tmp_path / "job.gcode"
    job.write_text(gcode(PROGRAM))
    n_b = sum(" B" in line for line in gcode(PROGRAM).splitlines())
    rc = plan_cli.run(parse([str(job), "--method", "heuristic", "--ignore-letters", "B"]))
    out = capsys.readouterr()
    assert f"dropped {n_b} B word(s)" in out.err
    assert rc == 0 and "violations    0" in out.out
    # the CAM's own time estimate beside the planned one; F caps the plan, which is
    # therefore never faster than the program says (and slower only by its accelerations)
    planned = float(re.search(r"^duration\s+([0-9.]+)", out.out, re.M).group(1))
    program = float(re.search(r"^program says\s+([0-9.]+)", out.out, re.M).group(1))
    assert 0.99 * program <= planned <= 1.5 * program


def test_g92_resets_keep_the_mandrel_axis_unwrapped():
    res = read_gcode(gcode(replace(PROGRAM, hoop=False, circuits=3)),
                     **load_config("winder3").gcode_options())
    c = res.points[:, 1]
    assert np.all(np.diff(c) >= 0)  # the program's A restarts at 0, the machine's C never
    per_circuit = 2 * (120.0 * math.degrees(1.0 / 100.0) + 558.0)
    assert c[-1] == pytest.approx(3 * per_circuit, abs=1e-3)  # 4 decimals a line
    assert set(np.round(res.points[:, 2], 9)) == {0.0, 45.0, -45.0}  # B: the eye's turns


def test_a_four_drive_program():
    text = "G21\nG90\nG0 F3000\n" + "\n".join(
        f"G0 X{i} Y{5 * math.sin(i / 10):.4f} A{i * 1.5:.4f} B{20 * math.cos(i / 20):.4f}"
        for i in range(1, 300))
    cfg = load_config("winder4")
    res = read_gcode(text, **cfg.gcode_options())
    assert res.points.shape == (299, 4)
    np.testing.assert_allclose(res.points[:, 1], 5 * np.sin(np.arange(1, 300) / 10), atol=1e-4)
    path = fit_points(res.points, np.asarray(cfg.machine.path_scale), "pchip")
    plan = make_planner("heuristic").plan(PlanRequest(path, cfg.machine.limits, PathState(0.0),
                                                      path.length, dt=cfg.machine.dt))
    samples = sample_profile(path, plan.profile, sample_times(plan.profile.duration,
                                                              cfg.machine.dt))
    checker = LimitChecker(cfg.machine.limits, cfg.machine.dt)
    checker.feed(samples.pos)
    assert checker.report().violations == 0
    np.testing.assert_allclose(samples.pos[-1], res.points[-1], atol=1e-6)


@pytest.mark.parametrize("dialect", ["marlin", "rs274"])
def test_what_f_caps_on_rotary_only_and_mixed_moves(dialect):
    """F600 (10 per s). marlin: 10 mm/s of path in the machine's metric on every move, G0
    too. rs274: G0 uncapped; F measures X when X moves, else A in deg/min, and the cap in
    the path metric makes each move take the time the program says."""
    scale_c = math.pi / 180 * 100.0
    text = "G21\nG90\nG1 F600 A90\nG1 X30 A90\nG1 X60 A180\nG0 X100\n"
    res = read_gcode(text, dialect=dialect, path_scale=[1.0, scale_c])
    if dialect == "marlin":
        np.testing.assert_allclose(res.feed, 10.0)
        lengths = [90 * scale_c, 30.0, math.hypot(30, 90 * scale_c), 40.0]
        assert res.programmed_time_s == pytest.approx(sum(lengths) / 10.0)
    else:
        assert res.feed[0] == pytest.approx(10.0 * scale_c)  # rotary only: 10 deg/s
        assert res.feed[1] == pytest.approx(10.0)  # linear only
        assert res.feed[2] == pytest.approx(10.0 * math.hypot(30, 90 * scale_c) / 30.0)
        assert np.isnan(res.feed[3])  # a rapid
        assert res.programmed_time_s == pytest.approx(9.0 + 3.0 + 3.0)


def test_marlin_time_is_fiberpaths_surface_arc_model():
    """Without B, the program's own estimate is the surface-arc time fiberpath uses:
    sum of hypot(dX, R dA) over the moves, divided by F (computed here independently)."""
    prog = replace(PROGRAM, delivery=False)
    cfg = build_config({})  # R = 100 mm
    res = read_gcode(gcode(prog), **cfg.gcode_options())
    pts = np.vstack([[0.0, 0.0], res.points])
    arc = np.hypot(np.diff(pts[:, 0]), np.radians(np.diff(pts[:, 1])) * 100.0)
    assert res.programmed_time_s == pytest.approx(arc.sum() / (6000.0 / 60.0), rel=1e-12)


def test_checker_allowance_at_a_million_degrees():
    """The rounding allowance 2^(n+1) eps |p| / dt^n at |p| = 1e6 deg, dt = 1 ms: velocity
    8.9e-7 deg/s, acceleration 1.8e-3 deg/s^2, jerk 3.6 deg/s^3 (1.2e-4 of 30000): an
    exactly jerk-limited motion there passes, one 0.1 % over the jerk limit is caught."""
    dt, jmax = 1e-3, 30000.0
    allowance = 16 * EPS * 1e6 / dt**3
    assert allowance == pytest.approx(3.55, abs=0.01) and allowance < 1e-3 * jmax
    t = np.arange(250) * dt  # acceleration stays below 1e4 (jmax t)
    from lookahead.limits import AxisLimits

    limits = AxisLimits(np.array([1e4]), np.array([1e4]), np.array([jmax]))
    for factor, violations in ((1.0, 0), (1.001, 1)):
        checker = LimitChecker(limits, dt)
        checker.feed((1e6 + factor * jmax * t**3 / 6).reshape(-1, 1))
        assert (checker.report().violations > 0) == bool(violations)


def test_large_mandrel_angles_keep_the_paths_precision():
    """The same stroke at C = 0 and at C = 190,000 deg: the same length to 1e-12, the same
    plan to 1e-6 (the offset moves the points by their last bits, ~3e-11 deg, and the
    planner's decisions amplify that: bench/replay_tolerance.py), the same motion relative
    to the start to 1e-6 deg, and the checker passes at both. The heuristic without
    valleys: a valley is a discrete choice at its checks' edges, and these last bits flip
    one (23 valley segments against 22, 0.22 % winding time; both plans pass the checker),
    which is the planner's choice, not the geometry's precision that this test is about."""
    t = np.linspace(0.0, 1.0, 300)
    stroke = np.column_stack([300.0 * t, 200.0 * t + 20.0 * np.sin(4 * np.pi * t)])
    cfg = build_config({})
    scale = np.asarray(cfg.machine.path_scale)
    results = []
    for offset in (0.0, 190_000.0):
        path = fit_points(stroke + np.array([0.0, offset]), scale, "cubic")
        request = PlanRequest(path, cfg.machine.limits, PathState(0.0), path.length, dt=1e-3)
        plan = HeuristicPlanner(margin=1.0, valleys=False).plan(request)
        pos = sample_profile(path, plan.profile, sample_times(plan.profile.duration, 1e-3)).pos
        checker = LimitChecker(cfg.machine.limits, 1e-3)
        checker.feed(pos)
        assert checker.report().violations == 0
        results.append((path.length, plan.profile.duration, pos - [0.0, offset]))
    (l0, d0, p0), (l1, d1, p1) = results
    assert l1 == pytest.approx(l0, rel=1e-12) and d1 == pytest.approx(d0, rel=1e-6)
    assert p0.shape == p1.shape and np.max(np.abs(p1 - p0)) < 1e-6


@pytest.mark.bus
def test_three_drive_demo_runs_end_to_end(tmp_path):
    """`lookahead demo --machine winder3 --fast`: service, 3-drive winder and publisher of a
    fiberpath-style program with B; the winder checks all three drives."""
    env = {**__import__("os").environ, "PYTHONUNBUFFERED": "1"}
    from lookahead.bus import free_tcp_endpoint

    env["LOOKAHEAD_ZENOH_LISTEN"] = free_tcp_endpoint()
    out = subprocess.run([sys.executable, "-m", "lookahead", "demo", "--machine", "winder3",
                          "--fast", "--out-dir", str(tmp_path), "--timeout", "300"],
                         env=env, capture_output=True, text=True, timeout=360)
    report = json.loads(Path(tmp_path, "report.json").read_text())[-1]
    assert report["axes"] == ["X", "C", "B"], out.stdout + out.stderr
    assert report["violations"] == 0 and report["gaps"] == 0
    assert report["duration_s"] > 10.0
    assert max(report["peak_fraction"]["v"]) > 0.1  # B moved too: it is really driven
    assert report["peak_fraction"]["v"][2] > 0.05
    assert out.returncode == 0, out.stdout + out.stderr
