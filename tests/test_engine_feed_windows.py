"""The engine's look-ahead window where segment feeds cap the feed (`Engine._window`).

The window is horizon_s of motion at the nominal top feed. A G-code job at F6000 (100 mm/s)
on the three-drive winder (top feed 1353 mm/s) made windows of 93 s of motion: cold LPs of
~2000 nodes that took up to 8.6 s, longer than any replan's lead. Where the caps hold the
feed below the top feed over the whole window, the window is horizon_s at the highest cap
there (at least three braking distances from it); where it reaches an uncapped stretch it
is the nominal one.
"""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import LimitChecker
from lookahead.config import default_config
from lookahead.planning.base import PlanRequest, PlanResult
from lookahead.protocol import Command, Segment
from lookahead.stream.engine import Engine, braking_distance
from lookahead.stream.planners import make_planner

AXES = ("X", "C")


class RecordingPlanner:
    """The engine's planner, recording each request's (start s, window end)."""

    def __init__(self, method: str) -> None:
        self.inner = make_planner(method)
        self.name = self.inner.name
        self.windows: list[tuple[float, float]] = []

    def plan(self, request: PlanRequest) -> PlanResult:
        self.windows.append((request.start.s, request.s_end))
        return self.inner.plan(request)

    def __getattr__(self, name: str):
        return getattr(self.inner, name)


def strokes(feeds: list[float | None], n: int = 301) -> list[Segment]:
    """One 300 mm helical stretch per feed (X 300 mm, C 2 turns), each a segment capped at
    that feed (mm/s; None: no cap)."""
    out = []
    for i, feed in enumerate(feeds):
        t = np.linspace(0.0, 1.0, n)[(1 if i else 0):]
        pts = np.column_stack([300.0 * (i + t), 720.0 * (i + t)])
        out.append(Segment("feeds", i, AXES, "points", i == len(feeds) - 1, points=pts,
                           feed=feed))
    return out


def run(engine: Engine, segments: list[Segment], commands=()) -> int:
    """Submit, produce every batch (checked at the limits), return the sample count."""
    for seg in segments:
        engine.submit(seg)
    for cmd in commands:
        engine.command(cmd)
    checker = LimitChecker(engine.limits, engine.dt)
    n = 0
    for _ in range(200_000):
        batch = engine.next_batch()
        if batch is None:
            continue
        checker.feed(batch.pos)
        n += batch.n
        if batch.final:
            assert checker.report().violations == 0
            return n
    raise AssertionError("the job did not finish")


def expected_window(engine: Engine, v: float) -> float:
    brake = braking_distance(engine.limits, engine.path_scale, v)
    return min(engine.horizon_len, max(engine.horizon_s * v, 3.0 * brake))


@pytest.mark.parametrize("method", ["heuristic", "lp"])
def test_capped_job_plans_windows_of_horizon_s_at_its_cap(method: str) -> None:
    cfg = default_config()
    planner = RecordingPlanner(method)
    engine = Engine(cfg, planner)
    cap = 40.0
    assert cap < float(np.linalg.norm(engine.limits.vmax * engine.path_scale))
    run(engine, strokes([cap] * 4))
    window = expected_window(engine, cap)
    assert window < 0.2 * engine.horizon_len
    lengths = [end - start for start, end in planner.windows]
    final = max(end for _, end in planner.windows)
    assert len(lengths) >= 5
    for (_, end), length in zip(planner.windows, lengths, strict=True):
        assert length <= window * (1 + 1e-9) or end >= final - 1e-6
    assert max(lengths) == pytest.approx(window, rel=1e-9)


def test_window_reaching_an_uncapped_stretch_is_the_nominal_one() -> None:
    cfg = default_config()
    planner = RecordingPlanner("heuristic")
    engine = Engine(cfg, planner)
    run(engine, strokes([40.0, 40.0, None, None, None]))
    # a window longer than the capped one is the nominal one (or ends at the job's end),
    # and windows from the capped strokes look across into the uncapped ones
    final = max(end for _, end in planner.windows)
    capped = expected_window(engine, 40.0)
    longer = [(start, end) for start, end in planner.windows
              if end - start > capped * (1 + 1e-9)]
    for start, end in longer:
        assert end - start == pytest.approx(engine.horizon_len) or end >= final - 1e-6
    stroke = float(np.hypot(300.0, 720.0 * engine.path_scale[1]))  # straight: exact length
    assert any(start < 2.0 * stroke for start, _ in longer)


def test_the_window_does_not_change_with_the_override() -> None:
    """Like `horizon_len`, in the nominal time frame: at override 0.5 the caps, scaled by
    the override, give the same windows."""
    cfg = default_config()
    lengths = []
    for f in (1.0, 0.5):
        planner = RecordingPlanner("heuristic")
        engine = Engine(cfg, planner)
        run(engine, strokes([40.0] * 3), [Command("override", f)])
        lengths.append(max(end - start for start, end in planner.windows))
    assert lengths[0] == pytest.approx(lengths[1], rel=1e-9)
