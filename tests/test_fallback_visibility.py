"""A fallback is a failure, and visible (issue 13, items 2-4): counted in the engine's
status and in `job_finished`, logged at WARNING with the reason and the place on the path,
reported by the winder and by `lookahead plan`, which never prints a traceback for a
planning failure. The windowed engine on issue 13's paths makes no fallback."""

from __future__ import annotations

import argparse
import logging
import math
import queue
from types import SimpleNamespace

import numpy as np
import pytest

from heuristic_paths import issue13_fourier_points
from lookahead import plan_cli
from lookahead.checker import check_positions
from lookahead.config import default_config
from lookahead.planning.place import PlacedPlanningError, describe_place, point_index
from lookahead.protocol import Event, Segment
from lookahead.stream.engine import Engine
from lookahead.stream.planners import make_planner
from lookahead_clients.winder import job_fallbacks

AXES = ("X", "C")


class FailingPlanner:
    """A planner named like the LP that always fails at a known place (s = 12.5)."""

    name = "lp"

    def plan(self, request):
        raise PlacedPlanningError("lp: no feasible plan (test)", request.start.s + 12.5)


def _segments(job: str, pts: np.ndarray, size: int = 200) -> list[Segment]:
    chunks = [pts[i:i + size] for i in range(0, len(pts), size)]
    return [Segment(job, i, AXES, "points", i == len(chunks) - 1, points=c)
            for i, c in enumerate(chunks)]


def _run(engine: Engine, segs: list[Segment], limit: int = 200000):
    for seg in segs:
        engine.submit(seg)
    out, events = [], []
    for _ in range(limit):
        batch = engine.next_batch()
        events += engine.drain_events()
        if batch is not None:
            out.append(batch.pos)
            if batch.final:
                return np.vstack(out), events
    raise AssertionError("the job did not finish")


def _small_job() -> np.ndarray:
    t = np.linspace(0.0, 1.0, 300)
    return np.column_stack([200.0 * np.sin(2 * np.pi * t), 720.0 * t])


def test_fallbacks_are_counted_in_status_and_job_finished_and_logged(caplog):
    cfg = default_config()
    engine = Engine(cfg, FailingPlanner())
    with caplog.at_level(logging.WARNING, logger="lookahead.engine"):
        pos, events = _run(engine, _segments("fb", _small_job()))
    assert check_positions(pos, cfg.machine.limits, cfg.machine.dt).ok
    assert engine.fallbacks > 0
    assert engine.status().fallbacks == engine.fallbacks
    finished = [e for e in events if e.type == "job_finished"]
    assert len(finished) == 1 and finished[0].extra["fallbacks"] == engine.fallbacks
    assert Event.decode(finished[0].encode()).extra["fallbacks"] == engine.fallbacks
    warned = [r for r in caplog.records if r.levelno == logging.WARNING and "fallback" in
              r.getMessage()]
    assert len(warned) == engine.fallbacks
    first = warned[0].getMessage()
    assert "no feasible plan (test)" in first and "s=12.5 (point" in first


def test_a_second_job_counts_only_its_own_fallbacks():
    cfg = default_config()
    engine = Engine(cfg, FailingPlanner())
    _, events = _run(engine, _segments("a", _small_job()))
    before = engine.fallbacks
    back = _small_job()[::-1]
    _, events = _run(engine, _segments("b", back))
    finished = [e for e in events if e.type == "job_finished"]
    assert finished[0].extra["fallbacks"] == engine.fallbacks - before > 0


def test_lp_engine_job_reports_zero_fallbacks():
    cfg = default_config()
    engine = Engine(cfg, make_planner("lp"))
    _, events = _run(engine, _segments("ok", _small_job()))
    finished = [e for e in events if e.type == "job_finished"]
    assert finished[0].extra["fallbacks"] == 0 and engine.status().fallbacks == 0


def test_point_index_names_the_knot_before_s():
    path = SimpleNamespace(breakpoints_s=lambda: np.array([0.0, 1.0, 2.5, 4.0]))
    assert [point_index(path, s) for s in (0.0, 0.99, 1.0, 3.0, 9.0)] == [0, 0, 1, 2, 3]
    assert describe_place(path, 3.0) == "s=3 (point 2)"


def test_winder_reads_fallbacks_from_job_finished():
    events: queue.Queue = queue.Queue()
    for job, n in (("other", 0), ("mine", 3)):
        payload = Event("job_finished", job, 10, {"duration_s": 1.0, "fallbacks": n}).encode()
        events.put(SimpleNamespace(kind="put", payload=payload))
    seen: dict[str, int] = {}
    assert job_fallbacks(events, seen, "mine") == 3
    assert job_fallbacks(events, seen, "other") == 0  # remembered while reading
    assert job_fallbacks(events, seen, "never") is None  # waits EVENT_GRACE_S, then None


def _parse(argv):
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    plan_cli.add_parser(sub)
    return parser.parse_args(["plan", *argv])


def _csv(tmp_path):
    th = np.linspace(0.0, 1.0, 60)
    pts = np.c_[100.0 * th, 200.0 * th + 20.0 * np.sin(6 * th)]
    csv = tmp_path / "job.csv"
    csv.write_text("X,C\n" + "\n".join(f"{x},{c}" for x, c in pts))
    return csv


def test_plan_cli_planning_failure_is_one_line_and_exit_1(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(plan_cli, "load_planner", lambda method: FailingPlanner())
    rc = plan_cli.run(_parse([str(_csv(tmp_path)), "--method", "lp"]))
    captured = capsys.readouterr()
    assert rc == 1
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err + captured.out
    assert "lp failed at s=12.5 (point" in lines[0] and "no feasible plan (test)" in lines[0]


def test_plan_cli_summary_lists_fallbacks(tmp_path, capsys):
    rc = plan_cli.run(_parse([str(_csv(tmp_path)), "--method", "lp"]))
    text = capsys.readouterr().out
    assert rc == 0 and "fallbacks     0" in text


# --- issue 13's paths through the windowed engine ---------------------------------------

def sine_eased_tube(length: float, radius: float, alpha_deg: float, passes: int = 1,
                    spacing: float = 2.0, dwell_deg: float = 180.0) -> np.ndarray:
    """Helical strokes X 0..length (mm), C = X / (R cot alpha) (deg); at each end a
    turnaround where dX/dC eases as cos(pi tau) while C keeps turning over dwell_deg."""
    k = radius / math.tan(math.radians(alpha_deg))  # mm per rad
    th = math.radians(dwell_deg)
    pts, x, c, sign = [np.zeros(2)], 0.0, 0.0, 1.0
    for _ in range(2 * passes):
        n = max(1, math.ceil(length / math.cos(math.radians(alpha_deg)) / spacing))
        xs = x + sign * np.linspace(0.0, length, n + 1)[1:]
        cs = c + np.linspace(0.0, length / k, n + 1)[1:]
        pts.extend(np.column_stack([xs, np.degrees(cs)]))
        x, c = xs[-1], cs[-1]
        m = max(8, math.ceil(math.hypot(0.64 * k * th, radius * th) / spacing))
        tau = np.linspace(0.0, 1.0, m + 1)[1:]
        xs = x + sign * k * th / math.pi * np.sin(math.pi * tau)
        cs = c + th * tau
        pts.extend(np.column_stack([xs, np.degrees(cs)]))
        x, c, sign = xs[-1], cs[-1], -sign
    return np.array(pts)




@pytest.mark.parametrize("name, points", [
    ("tube-1450-sine", lambda: sine_eased_tube(1450.0, 100.0, 45.0)),
    # before issue 13's fixes: 24 fallbacks (every LP window from the first infeasible)
    ("fourier-3000", issue13_fourier_points),
])
def test_windowed_engine_on_issue_paths_makes_no_fallback(name, points):
    cfg = default_config()
    engine = Engine(cfg, make_planner("lp"))
    pos, events = _run(engine, _segments(name.replace("-", "_"), points()))
    assert check_positions(pos, cfg.machine.limits, cfg.machine.dt).ok
    assert engine.fallbacks == 0
    assert [e.extra["fallbacks"] for e in events if e.type == "job_finished"] == [0]


class HandingOverPlanner:
    """The heuristic, named like the LP, whose every plan says that its start was handed
    over (`lp.handover`'s info), as an LP plan whose transient the heuristic made."""

    name = "lp"

    def __init__(self) -> None:
        self.inner = make_planner("heuristic")

    def plan(self, request):
        result = self.inner.plan(request)
        info = {**result.info, "handover": {"t": 0.01, "s": request.start.s + 1.0, "v": 1.0,
                                            "share": 0.01, "whole": False, "attempt": 0,
                                            "reason": "lp: test"}}
        return type(result)(result.profile, "lp", result.compute_s, info)


def test_handovers_are_counted_in_job_finished_and_logged_not_as_fallbacks(caplog):
    """A plan whose start was handed over is not a fallback: counted apart
    (`Engine.handovers`, `job_finished.handovers`), logged at INFO with the place and the
    LP's reason."""
    cfg = default_config()
    engine = Engine(cfg, HandingOverPlanner())
    with caplog.at_level(logging.INFO, logger="lookahead.engine"):
        _, events = _run(engine, _segments("ho", _small_job()))
    finished = [e for e in events if e.type == "job_finished"]
    assert engine.handovers == engine.replans > 0 and engine.fallbacks == 0
    assert Event.decode(finished[0].encode()).extra["handovers"] == engine.handovers
    logged = [r.getMessage() for r in caplog.records if "handed over" in r.getMessage()]
    assert len(logged) == engine.handovers and "lp: test" in logged[0]
