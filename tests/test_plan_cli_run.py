"""`lookahead plan` on a points file: summary, npz output, plot, exit status."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from lookahead import plan_cli


def parse(argv):
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    plan_cli.add_parser(sub)
    return parser.parse_args(["plan", *argv])


def test_plan_points_csv_writes_npz(tmp_path, capsys):
    th = np.linspace(0.0, 1.0, 60)
    pts = np.c_[100.0 * th, 200.0 * th + 20.0 * np.sin(6 * th)]
    pts = np.vstack([pts, pts[-1:]])  # a repeated point is skipped
    csv = tmp_path / "job.csv"
    csv.write_text("X,C\n" + "\n".join(f"{x},{c}" for x, c in pts))
    out = tmp_path / "job.npz"
    rc = plan_cli.run(parse([str(csv), "--method", "heuristic", "--out", str(out)]))
    text = capsys.readouterr().out
    assert rc == 0
    assert "violations    0" in text
    data = np.load(out)
    assert data["pos"].shape[1] == 2 and data["pos"].shape == data["vel"].shape
    np.testing.assert_allclose(data["pos"][0], pts[0], atol=1e-9)
    np.testing.assert_allclose(data["pos"][-1], pts[-1], atol=1e-6)
    assert float(data["dt"]) == pytest.approx(0.001)
    assert list(data["axes"]) == ["X", "C"]


def test_plan_bad_input_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("X,Y\n1,2\n3,4\n")
    assert plan_cli.run(parse([str(bad), "--method", "heuristic"])) == 2
    assert "lookahead plan" in capsys.readouterr().err


def test_plot_is_written(tmp_path):
    pytest.importorskip("matplotlib")
    pts = np.c_[np.linspace(0, 50, 20), np.linspace(0, 90, 20) ** 1.1]
    npy = tmp_path / "p.npy"
    np.save(npy, pts)
    png = tmp_path / "p.png"
    assert plan_cli.run(parse([str(npy), "--method", "heuristic", "--plot", str(png)])) == 0
    assert png.stat().st_size > 10_000


def test_a_preset_name_is_an_input_too(tmp_path, capsys, monkeypatch):
    """`lookahead plan tube-1450` plans the preset, as `lookahead publish tube-1450` sends
    it; a file of that name in the working directory would win."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "preset.npz"
    assert plan_cli.run(parse(["tube-1450", "--method", "heuristic", "--out", str(out)])) == 0
    assert "violations    0" in capsys.readouterr().out
    from lookahead.geometry.winding import preset_points

    _, pts, _ = preset_points("tube-1450")
    np.testing.assert_allclose(np.load(out)["pos"][-1], pts[-1], atol=1e-6)
    (tmp_path / "tube-1450").write_text("X,C\n0,0\n")  # one point: not a path
    assert plan_cli.run(parse(["tube-1450", "--method", "heuristic"])) == 2
