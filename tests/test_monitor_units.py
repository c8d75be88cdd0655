"""The monitor's pieces without a bus: finite differences and decimation of the chart
against the independent checker, the programmed path and progress along it, and a
machine view fed by hand."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lookahead.checker import LimitChecker
from lookahead.limits import AxisLimits
from lookahead.protocol import Event, Segment, SetpointBatch, Status
from lookahead_clients.monitor.chart import ChartBinner
from lookahead_clients.monitor.machine_view import MachineSpec, MachineView
from lookahead_clients.monitor.path_view import ProgrammedPath, segment_points
from lookahead_clients.status import describe

DT = 0.001
VMAX, AMAX, JMAX = (500.0, 720.0), (2000.0, 3000.0), (20000.0, 30000.0)


def wobble(n: int, seed: int = 1) -> np.ndarray:
    """A smooth two-axis motion (mm, deg) with a few sharper features."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    x = 80 * np.sin(2.1 * t) + 3 * np.sin(37 * t + rng.uniform(0, 6))
    c = 120 * t + 40 * np.sin(5.3 * t) ** 3
    return np.column_stack([x, c])


@pytest.mark.parametrize("cuts", [[], [7], [1, 2, 3, 50, 51, 999, 1500]])
def test_chart_peaks_are_the_checkers_and_batches_do_not_matter(cuts):
    pos = wobble(3000)
    binner = ChartBinner(VMAX, AMAX, JMAX, (1.0, 1.0), DT)
    rows = []
    for lo, hi in zip([0, *cuts], [*cuts, len(pos)], strict=True):
        rows += binner.add(lo, pos[lo:hi])
    rows += binner.close()
    checker = LimitChecker(AxisLimits(np.array(VMAX), np.array(AMAX), np.array(JMAX)), DT)
    checker.feed(pos)
    peak = checker.report().peak_fraction
    for i, kind in enumerate("vaj"):
        np.testing.assert_allclose(binner.peak[i], peak[kind], rtol=1e-12)
        # decimation keeps the peak: the largest bin is the job's peak
        np.testing.assert_allclose(np.max([getattr(r, kind) for r in rows], axis=0),
                                   peak[kind], rtol=1e-12)
    assert len(rows) == 3000 // 20 and [r.id for r in rows] == list(range(len(rows)))
    assert rows[-1].t == pytest.approx(2.999) and rows[-1].pos == pos[-1].tolist()
    assert binner.gaps == 0


def test_chart_feed_is_the_scaled_speed_and_a_gap_restarts_the_differences():
    scale = (1.0, np.pi / 180 * 100)
    k = np.arange(200)
    pos = np.column_stack([3.0 * 0.1 * k * DT * 1000, 0.2 * k])  # 300 mm/s, 200 deg/s
    binner = ChartBinner(VMAX, AMAX, JMAX, scale, DT)
    rows = binner.add(0, pos[:100])
    expect = np.hypot(300.0, 200.0 * scale[1])
    assert rows[-1].feed == pytest.approx(expect)
    assert rows[-1].v == pytest.approx([300 / 500, 200 / 720])
    # samples 100..149 never arrive: no difference is taken across the hole
    rows = binner.add(150, pos[150:]) + binner.close()
    assert binner.gaps == 1
    assert max(r.a[0] for r in rows) == pytest.approx(0.0, abs=1e-6)
    assert binner.since(rows[0].id)[0] is rows[0] and binner.since(10**6) == []


def points_segment(job: str, seq: int, pts, last: bool) -> Segment:
    return Segment(job, seq, ("X", "C"), "points", last, points=np.asarray(pts, float))


def test_progress_follows_a_self_crossing_path_in_order():
    # out along one diagonal, down the side, back along the other diagonal: the crossing
    # at (5, 5) must not make progress jump from the first pass to the second
    out = np.column_stack([np.linspace(0, 10, 11), np.linspace(0, 10, 11)])
    down = np.column_stack([np.full(10, 10.0), np.linspace(9, 0, 10)])
    back = np.column_stack([np.linspace(9, 0, 10), np.linspace(1, 10, 10)])
    path = ProgrammedPath("j", (1.0, 1.0))
    path.add(points_segment("j", 1, np.vstack([down, back]), True))
    assert path.segments == 1 and not path.complete  # seq 0 missing: no polyline yet
    assert path.progress(path.locate(np.array([1.0, 1.0]))) is None
    path.add(points_segment("j", 0, out, False))
    path.add(points_segment("j", 0, out, False))  # a repeat is ignored
    total = 20 * np.sqrt(2) + 10
    assert path.complete and path.length == pytest.approx(total)
    fractions = [path.progress(path.locate(p)) for p in np.vstack([out, down, back])]
    assert fractions[0] == 0.0 and fractions[-1] == pytest.approx(1.0)
    assert all(b > a for a, b in itertools.pairwise(fractions))
    assert fractions[5] == pytest.approx(5 * np.sqrt(2) / total)  # (5, 5) on the way out
    assert fractions[-6] == pytest.approx(1 - 5 * np.sqrt(2) / total)  # ... and back


def test_a_nurbs_segment_is_drawn_on_its_circle():
    w = np.sqrt(0.5)  # a quarter circle of radius 2 as a rational quadratic
    seg = Segment("j", 0, ("X", "C"), "nurbs", True, degree=2,
                  knots=np.array([0, 0, 0, 1, 1, 1.0]),
                  ctrl=np.array([[2.0, 0], [2, 2], [0, 2]]), weights=np.array([1, w, 1]))
    pts = segment_points(seg)
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 2.0, atol=1e-12)
    path = ProgrammedPath("j", (1.0, 1.0))
    path.add(seg)
    assert path.length == pytest.approx(np.pi, rel=1e-3)


def spec() -> MachineSpec:
    return MachineSpec("m", "lookahead/m", ("X", "C"), ("mm", "deg"), VMAX, AMAX, JMAX,
                       (1.0, 1.0), DT)


def batch(job: str, seq: int, k0: int, pos: np.ndarray, final: bool) -> SetpointBatch:
    return SetpointBatch(job, seq, k0, DT, ("X", "C"), pos, pos * 0, pos * 0, final)


def test_a_view_reports_progress_and_what_it_is_based_on():
    view = MachineView(spec())
    snap = view.snapshot()
    assert snap["service"] == "checking" and snap["progress"]["fraction"] is None
    view.on_alive("planner", False)
    assert view.snapshot()["service"] == "none"
    view.on_alive("planner", True)
    pts = np.column_stack([np.linspace(0, 100, 50), np.linspace(0, 50, 50)])
    view.on_segment(points_segment("a", 0, pts, True))
    pos = np.column_stack([np.linspace(0, 100, 400), np.linspace(0, 50, 400)])
    view.on_setpoints([batch("a", 0, 0, pos[:200], False)])
    snap = view.snapshot()
    assert snap["job"] == "a" and snap["progress"]["fraction"] == pytest.approx(0.5, abs=0.01)
    assert "programmed path" in snap["progress"]["basis"] and snap["path"]["complete"]
    again = view.snapshot(snap["next_row"], snap["next_event"],
                          (snap["path"]["job"], snap["path"]["version"]))
    assert again["rows"] == [] and "path" not in again  # nothing new since the cursors
    view.on_setpoints([batch("a", 1, 200, pos[200:300], False),
                       batch("a", 2, 300, pos[300:], True)])
    view.on_event(Event("job_finished", "a", 399, {"duration_s": 0.399}))
    snap = view.snapshot()
    assert snap["progress"]["fraction"] == pytest.approx(1.0)
    assert snap["progress"]["duration_s"] == 0.399 and snap["events"][-1]["type"] == \
        "job_finished"
    # a job whose segments the monitor never saw: progress unknown, and it says why
    view.on_setpoints([batch("b", 0, 0, pos[:100], False)])
    snap = view.snapshot()
    assert snap["job"] == "b" and snap["progress"]["fraction"] is None
    assert "did not see" in snap["progress"]["basis"]


def test_time_left_is_shown_only_once_the_plan_reaches_the_end():
    view = MachineView(spec())
    view.on_segment(points_segment("t", 0, np.array([[0.0, 0.0], [100.0, 50.0]]), True))
    view.on_status(Status("running", "t", 500, 1, 2.5, 1.0, "lp", 1.0, None))
    progress = view.snapshot()["progress"]
    assert progress["remaining_s"] is None and progress["planned_ahead_s"] == 2.5
    assert progress["elapsed_s"] == pytest.approx(0.5)
    view.on_status(Status("running", "t", 1500, 1, 1.25, 1.0, "lp", 1.0, None,
                          plan_complete=True, remaining_s=1.25))
    progress = view.snapshot()["progress"]
    assert progress["remaining_s"] == 1.25 and progress["elapsed_s"] == pytest.approx(1.5)
    # another job's status says nothing about this one
    view.on_status(Status("running", "other", 10, 0, 1.0, 1.0, "lp", 1.0, None,
                          plan_complete=True, remaining_s=1.0))
    assert view.snapshot()["progress"]["remaining_s"] is None


def test_lookahead_status_prints_the_time_left():
    running = Status("running", "t", 1500, 1, 1.25, 1.0, "lp", 1.0, None,
                     plan_complete=True, remaining_s=1.2504)
    line = describe("lookahead/winder", running)
    assert line.startswith("lookahead/winder: state=running job=t k=1500 ")
    assert line.endswith(" horizon_s=1.250 override=1.0 planner=lp plan_ms=1.00 error=None "
                         "plan_complete=True remaining_s=1.250")
    ahead = Status("running", "t", 10, 1, 2.0, 1.0, "lp", 1.0, None)
    assert describe("ns", ahead).endswith(" plan_complete=False remaining_s=None")
