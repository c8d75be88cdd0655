"""The status' time left without a bus (issue 18): `plan_complete` turns true once the
committed plan reaches the job's end, and `remaining_s` is then the exact motion time to the
job's last sample, also after an override, a hold and an abort (engine "Time left")."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lookahead.config import default_config
from lookahead.protocol import Command, Segment, SetpointBatch, Status
from lookahead.stream.engine import Engine
from lookahead.stream.planners import make_planner

AXES = ("X", "C")


def long_points(n: int = 1200, strokes: int = 4) -> np.ndarray:
    """`strokes` X strokes of 300 mm while C turns 5 turns per stroke (4: several
    look-ahead windows long, ~11 s)."""
    t = np.linspace(0.0, 1.0, n)
    return np.column_stack([150.0 * (1.0 - np.cos(2.0 * strokes * np.pi * t)),
                            1800.0 * strokes * t])


def segments(job: str, pts: np.ndarray, size: int = 100) -> list[Segment]:
    chunks = [pts[i:i + size + 1] for i in range(0, len(pts) - 1, size)]
    return [Segment(job, i, AXES, "points", i == len(chunks) - 1, points=c)
            for i, c in enumerate(chunks)]


def run(engine: Engine, script: dict[int, list[Command]] | None = None,
        limit: int = 200000) -> tuple[list[SetpointBatch], list[tuple[int, Status]]]:
    """next_batch until the job ends; before call i apply script[i]. Returns the batches
    and (call index, status) after each command and each batch but the last (through the
    wire format)."""
    batches, statuses = [], []
    for i in range(limit):
        if batches and batches[-1].final:
            # after the last batch the engine is idle: no job, nothing to count down
            st = engine.status()
            assert st.state == "idle" and not st.plan_complete and st.remaining_s is None
            return batches, statuses
        for cmd in (script or {}).get(i, []):
            assert engine.command(cmd).ok
            statuses.append((i, Status.decode(engine.status().encode())))
        batch = engine.next_batch()
        if batch is None:
            continue
        batches.append(batch)
        if not batch.final:
            statuses.append((i, Status.decode(engine.status().encode())))
    raise AssertionError("the job did not finish")


def last_k(batches: list[SetpointBatch]) -> int:
    return batches[-1].k0 + batches[-1].n - 1


def assert_exact_once_complete(statuses: list[Status], k_final: int, dt: float) -> None:
    """Every complete status: remaining_s = (k_final - k) dt; incomplete ones carry None."""
    for st in statuses:
        if st.plan_complete:
            assert st.remaining_s == pytest.approx((k_final - st.k) * dt, abs=1e-9), st
            assert st.remaining_s == st.horizon_s
        else:
            assert st.remaining_s is None, st


@pytest.fixture(scope="module")
def cfg():
    return default_config()


def test_a_long_job_is_first_incomplete_then_exact_to_its_last_sample(cfg):
    engine = Engine(cfg, make_planner("heuristic"))
    for seg in segments("long", long_points()):
        engine.submit(seg)
    batches, pairs = run(engine)
    statuses = [st for _, st in pairs]
    dt = cfg.machine.dt
    k_final = last_k(batches)
    flags = [st.plan_complete for st in statuses]
    first = flags.index(True)
    # the path is several windows long: the end is planned only after a while, and once
    # planned it stays planned (no command): false ... false, true ... true
    assert statuses[first].k * dt > 1.0, statuses[first]
    assert not any(flags[:first]) and all(flags[first:])
    assert all(st.horizon_s > 0.0 for st in statuses[:first])
    assert_exact_once_complete(statuses, k_final, dt)
    rem = [st.remaining_s for st in statuses[first:]]
    assert all(b < a for a, b in itertools.pairwise(rem))  # it counts down
    assert rem[-1] == pytest.approx(batches[-1].n * dt) and rem[0] > 1.0


def test_a_job_whose_end_has_not_arrived_is_incomplete_even_at_rest(cfg):
    engine = Engine(cfg, make_planner("heuristic"))
    segs = segments("late", long_points(400), 100)
    for seg in segs[:-1]:
        engine.submit(seg)
    moved = [b for b in (engine.next_batch() for _ in range(5000)) if b is not None]
    st = engine.status()
    assert moved and st.state == "starved"  # at rest at the end of what it received
    assert not st.plan_complete and st.remaining_s is None and st.horizon_s == 0.0
    engine.submit(segs[-1])  # the `last` segment: now the end can be planned
    batches, pairs = run(engine)
    statuses = [st for _, st in pairs]
    assert_exact_once_complete(statuses, last_k(batches), cfg.machine.dt)
    assert statuses[-1].plan_complete
    assert statuses[-1].remaining_s == pytest.approx(batches[-1].n * cfg.machine.dt)
    assert any(st.plan_complete and st.remaining_s > 0.1 for st in statuses)


def predicted_ends(pairs: list[tuple[int, Status]], dt: float) -> list[tuple[int, int]]:
    """(call index, k + remaining_s / dt rounded) of every complete status."""
    return [(i, st.k + round(st.remaining_s / dt)) for i, st in pairs if st.plan_complete]


@pytest.mark.parametrize(("planner", "realtime"), [("heuristic", False), ("lp", True)])
def test_override_hold_and_resume_are_recomputed_and_holds_not_counted(cfg, planner,
                                                                        realtime):
    """A job planned to its end from ~0.8 s on (real time ~2.0 s: replans take over ahead
    of the last sample, as late as 0.2 s before the plan in force brakes); commands before
    calls 100 (real time 220; override 0.6: slower), 160 (320; hold), 300 (400; resume)
    and 360 (460; override 1.0: faster again): false/None from each command until the
    plan is remade, then one predicted end until the next command, the true end after the
    last. Real time: an override's end is known once the LP's replan computed ahead takes
    over from the bridge (`_commit_command`, ~0.7 s later); the hold's rest samples count
    as job time once they are published, never before."""
    engine = Engine(cfg, make_planner(planner), realtime=realtime)
    for seg in segments("cmds", long_points(300, strokes=1)):
        engine.submit(seg)
    first, hold, resume, faster = (220, 320, 400, 460) if realtime else (100, 160, 300, 360)
    script = {first: [Command("override", 0.6)], hold: [Command("hold")],
              resume: [Command("resume")], faster: [Command("override", 1.0)]}
    batches, pairs = run(engine, script)
    dt = cfg.machine.dt
    k_final = last_k(batches)
    for _, st in pairs:
        assert (st.remaining_s is not None) == st.plan_complete, st
        if st.plan_complete:
            assert st.remaining_s == st.horizon_s
    after_command = {i: st for i, st in reversed(pairs) if i in script}  # the first at i
    assert sorted(after_command) == sorted(script)
    for i, st in after_command.items():  # a command voids the time left until replanned
        assert not st.plan_complete, (i, st)
    holding = [st for _, st in pairs if st.state == "holding"]
    assert holding and not any(st.plan_complete for st in holding)
    ends = predicted_ends(pairs, dt)
    marks = [0, *sorted(script), 10**9]
    spans = [{e for i, e in ends if lo <= i < hi} for lo, hi in itertools.pairwise(marks)]
    # exactly one predicted end between two commands but while holding (hold..resume)
    assert [len(span) for span in spans] == [1, 1, 0, 1, 1], spans
    (full, slow, _, resumed, final) = (min(span, default=None) for span in spans)
    assert final == k_final
    assert slow > full  # override 0.6: the end moves later
    # resumed from rest after the hold (at 0.6): later than before it, by the stop, the
    # restart and (real time) the rest samples already published, no guess at the hold
    assert resumed > slow
    assert final < resumed  # back to 1.0: sooner


def test_an_abort_plans_the_stop_and_its_time_is_exact(cfg):
    engine = Engine(cfg, make_planner("heuristic"))
    for seg in segments("abort", long_points()):
        engine.submit(seg)
    batches, pairs = run(engine, {100: [Command("abort")]})
    k_final = last_k(batches)
    dt = cfg.machine.dt
    assert batches[-1].final and k_final * dt < 3.0  # stopped well before the path's end
    after = [st for i, st in pairs if i >= 100]
    assert not after[0].plan_complete  # the abort waits for the next batch to plan its stop
    assert all(st.plan_complete for st in after[1:])
    assert_exact_once_complete(after, k_final, dt)
    assert not any(st.plan_complete for i, st in pairs if i < 100)
