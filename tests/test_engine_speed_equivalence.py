"""The engine's speed work changes no result: each faster computation against an
independent slow one (issues 13/14, bench/engine_profile.py).

- samples of a committed plan (computed once per plan, sliced per batch) against the
  profile sampled one time at a time; its path-state table against `FeedProfile.at`;
- `Path.eval_s` of orders 0-2 (only the derivatives asked for) against order 3;
- the arc-length speed of a polynomial curve (dx/du only) against the full evaluation;
- the checker (three orders stacked, small batches checked together) against the
  docstring's formula applied order by order to the whole stream;
- fit-excursion warnings (own-chord bound first) against measuring every sample;
- the replan cadence: the engine replans only when its plan looks ahead less than the
  keep distance, still replans as geometry streams in, and every plan it commits passes
  the checker with the published tail (as before);
- the geometry a segment and a batch touch: the excursion check measures the fit's final
  pieces (`StreamingFit.final_path`, bit for bit the live path there) without building
  the tail; a batch between replans asks nothing of the geometry; the per-batch memos
  give the batches of deciding afresh.
"""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.checker import LimitChecker, Violation
from lookahead.config import default_config
from lookahead.geometry.deviation import PolylineDistance, excursion_runs, interval_excursions
from lookahead.geometry.fits import fit_path
from lookahead.limits import AxisLimits
from lookahead.planning.base import PathState, PlanRequest
from lookahead.planning.heuristic import HeuristicPlanner
from lookahead.protocol import Segment
from lookahead.sampling import sample_profile
from lookahead.stream import engine as engine_mod
from lookahead.stream import plans as plans_mod
from lookahead.stream.engine import Engine
from lookahead.stream.plans import CommittedPlan, verify

AXES = ("X", "C")


def _wavy(n: int = 600, turns: float = 3.0) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    return np.column_stack([400.0 * t + 40.0 * np.sin(2 * np.pi * turns * t), 1440.0 * t])


def _segments(job: str, pts: np.ndarray, size: int) -> list[Segment]:
    chunks = [pts[i:i + size] for i in range(0, len(pts), size)]
    return [Segment(job, i, AXES, "points", i == len(chunks) - 1, points=c)
            for i, c in enumerate(chunks)]


def _plan(path, limits, start: PathState, s_end: float, dt: float):
    return HeuristicPlanner(margin=1.0).plan(PlanRequest(path, limits, start, s_end, dt=dt))


# --- samples and path states of a committed plan -------------------------------------


@pytest.fixture(scope="module")
def committed():
    cfg = default_config()
    m = cfg.machine
    path = fit_path(_wavy(), np.asarray(m.path_scale), "cubic")
    lim = m.limits.scaled(0.98)
    first = CommittedPlan.anchor(path, _plan(path, lim, PathState(0.0), 0.6 * path.length,
                                             m.dt), 0, m.dt)
    first, _ = first.with_samples(m.dt)
    k = (first.k_end - first.k_plan) // 2
    st = first.state(k, m.dt)
    second = CommittedPlan.anchor(path, _plan(path, lim, st, path.length, m.dt), k, m.dt)
    second, k_new = second.with_samples(m.dt, first)
    return m.dt, first, second, k_new


def test_plan_samples_equal_the_profile_sampled_one_time_at_a_time(committed):
    dt, first, second, _ = committed
    for plan in (first, second):
        ks = np.arange(plan.k_plan + 1, plan.k_end + 4)
        got = plan.samples(int(ks[0]), ks.size, dt)
        for f in ("pos", "vel", "acc"):
            want = np.vstack([getattr(sample_profile(plan.path, plan.profile,
                                                     np.array([(k - plan.k_plan) * dt])), f)
                              for k in ks[::7]])
            # one time at a time vs all at once differ only by the BLAS rounding of the
            # chain rule's weighted sums (a few ulps)
            scale = 1.0 + np.max(np.abs(want), axis=0)
            assert np.all(np.abs(getattr(got, f)[::7] - want) <= 1e-12 * scale), f


def test_state_table_is_the_profile_evaluated_at_each_sample(committed):
    dt, first, second, _ = committed
    for plan in (first, second):
        for k in range(plan.k_plan + 1, plan.k_end + 4, 13):
            s, v, a, _ = plan.profile.at(np.array([(k - plan.k_plan) * dt]))[:, 0]
            want = PathState(plan.s_end) if k >= plan.k_end else PathState(
                float(s), max(float(v), 0.0), float(a))
            assert plan.state(k, dt) == want  # exact: FeedProfile.at is pointwise


def test_replan_reuses_samples_only_where_it_equals_the_previous_plan(committed):
    """Samples before k_new are the previous plan's (its path state equal to rounding);
    from k_new on they are the new plan's own, sampled over exactly that range."""
    dt, first, second, k_new = committed
    k0 = second.k_plan + 1
    assert k0 <= k_new <= second.k_end + 3
    if k_new > k0:
        np.testing.assert_array_equal(second.samples(k0, k_new - k0, dt).pos,
                                      first.samples(k0, k_new - k0, dt).pos)
        mine, theirs = (p.profile.at(p.times(np.arange(k0, k_new), dt))[:3]
                        for p in (second, first))
        assert np.allclose(mine, theirs, rtol=1e-9, atol=1e-9)
    own = sample_profile(second.path, second.profile,
                         second.times(np.arange(k_new, second.k_end + 4), dt))
    np.testing.assert_array_equal(second.samples(k_new, len(own), dt).pos, own.pos)


# --- geometry evaluation ---------------------------------------------------------------


@pytest.mark.parametrize("method", ["cubic", "pchip", "linear"])
def test_eval_s_of_low_orders_equals_the_full_chain_rule(method):
    pts = _wavy(200)
    path = fit_path(pts, np.array([1.0, np.pi / 180 * 50.0]), method, 0.05)
    s = np.random.default_rng(2).uniform(0.0, path.length, 3001)
    full = path.eval_s(s, order=3)
    for order in (0, 1, 2):
        got = path.eval_s(s, order=order)
        assert got.shape == (order + 1, s.size, 2)
        np.testing.assert_array_equal(got, full[: order + 1])


def test_polynomial_speed_is_the_norm_of_dx_du():
    path = fit_path(_wavy(300), np.array([1.0, 0.8]), "cubic")
    u = np.random.default_rng(3).uniform(*path.u_range, 5000)
    xu = path.eval_u(u, order=1)[1]
    np.testing.assert_array_equal(path._speed(u),
                                  np.sqrt(np.sum((path.path_scale * xu) ** 2, axis=-1)))


# --- the checker -----------------------------------------------------------------------


def _slow_check(pos: np.ndarray, limits: AxisLimits, dt: float):
    """The module docstring's test, order by order over the whole stream at once."""
    eps = float(np.finfo(float).eps)
    counts, peaks, first = {}, {}, None
    for kind, order, lim in (("v", 1, limits.vmax), ("a", 2, limits.amax),
                             ("j", 3, limits.jmax)):
        d = np.diff(pos, n=order, axis=0)
        mag = np.max(np.stack([np.abs(pos[i:len(pos) - order + i])
                               for i in range(order + 1)]), axis=0)
        value = np.abs(d) / dt**order
        tol = lim * 1e-9 + 2.0 ** (order + 1) * eps * mag / dt**order
        over = value > lim + tol
        counts[kind] = over.sum(axis=0).tolist()
        peaks[kind] = np.max(value / lim, axis=0).tolist()
        if over.any():
            rows, cols = np.nonzero(over)
            if first is None or rows[0] < first.k:
                first = Violation(int(rows[0]), int(cols[0]), kind,
                                  float(value[rows[0], cols[0]]), float(lim[cols[0]]))
    return counts, peaks, first


@pytest.mark.parametrize("seed", range(10))
def test_checker_equals_the_formula_order_by_order(seed):
    rng = np.random.default_rng(seed)
    n, naxes = int(rng.integers(50, 5000)), int(rng.integers(1, 7))
    lim = AxisLimits(rng.uniform(1, 100, naxes), rng.uniform(10, 1e3, naxes),
                     rng.uniform(1e2, 1e5, naxes))
    noise = 10.0 ** rng.uniform(-9, -5)  # from no violation to many
    pos = 1e3 * rng.normal(size=naxes) + np.cumsum(np.cumsum(
        rng.normal(size=(n, naxes)) * noise, axis=0), axis=0)
    checker = LimitChecker(lim, 1e-3)
    cuts = np.sort(rng.choice(np.arange(1, n), size=min(n - 1, int(rng.integers(1, 400))),
                              replace=False))
    for part in np.split(pos, cuts):  # batches of 1, 2, ... rows, in any order of sizes
        checker.feed(part)
    rep = checker.report()
    counts, peaks, first = _slow_check(pos, lim, 1e-3)
    assert rep.samples == n
    assert rep.counts == counts and rep.peak_fraction == peaks and rep.first == first
    assert rep.violations == sum(map(sum, counts.values()))


# --- fit excursion warnings ------------------------------------------------------------


def _all_measured(path, points, k0, k1, tolerance, per_interval=16, context=4):
    """`interval_excursions` measuring every sample exactly (no chord bound)."""
    knots = path.breakpoints_u()
    lo, hi = max(k0 - context, 0), min(k1 + context + 1, len(points))
    frac = np.arange(1, per_interval) / per_interval
    u = (knots[k0:k1, None] + np.diff(knots)[k0:k1, None] * frac[None, :]).ravel()
    dev = PolylineDistance(points[lo:hi], path.path_scale)(path.eval_u(u, 0)[0])
    return excursion_runs(path, u, dev, tolerance)


def test_excursions_equal_measuring_every_sample():
    rng = np.random.default_rng(11)
    found = 0
    for _ in range(25):
        n = int(rng.integers(5, 250))
        pts = np.cumsum(rng.normal(size=(n, 3)) * rng.uniform(0.1, 5.0), axis=0)
        path = fit_path(pts, rng.uniform(0.5, 2.0, 3), rng.choice(["cubic", "pchip"]))
        for tol in (1e-3, 0.05, 0.5):
            k0 = int(rng.integers(0, n - 1))
            k1 = int(rng.integers(k0 + 1, n))
            got = interval_excursions(path, pts, k0, k1, tol)
            assert got == _all_measured(path, pts, k0, k1, tol)
            found += len(got)
    assert found > 50  # the comparison covered stretches beyond the tolerance


# --- the replan cadence ----------------------------------------------------------------


class _Recorder:
    """Wraps `plans.verify`: every (plan, result) the engine checked."""

    def __init__(self) -> None:
        self.calls: list[tuple[CommittedPlan, str | None]] = []

    def __call__(self, plan, tail, limits, dt, k_new=None):
        out = verify(plan, tail, limits, dt, k_new)
        self.calls.append((plan, out))
        return out


def _run(engine: Engine, feed: dict[int, list[Segment]]):
    batches, looks = [], []
    for i in range(200_000):
        for seg in feed.get(i, []):
            engine.submit(seg)
        job = engine._active
        before = job.plan if job is not None else None
        batch = engine.next_batch()
        job = engine._active
        if job is not None and before is not None and job.plan is not before:
            # a replan: how far the replaced plan looked ahead of the last sample
            k_last = job.k - 1 - (batch.n if batch is not None else 0)
            to_end = job.plan.s_end >= job.geo.path().length * (1 - 1e-9)
            looks.append((before.s_end - before.state(k_last, engine.dt).s, to_end))
        if batch is not None:
            batches.append(batch)
            if batch.final:
                return batches, looks
    raise AssertionError("the job did not finish")


@pytest.mark.parametrize("stream", [False, True])
def test_replans_only_when_looking_ahead_less_than_the_keep_distance(monkeypatch, stream):
    """Fewer replans, the same safety: every committed plan is checked with the published
    tail and passes; a replan comes only once the plan in force looks ahead <= keep (all
    geometry in; or once to plan the job's end), at most one per (window - keep) of path;
    streamed geometry still extends the plan as it arrives; and the motion takes no longer
    than with a replan every REPLAN_EVERY_S (the cadence before, `REPLAN_KEEP` = inf)."""
    cfg = default_config()
    m = cfg.machine
    segs = _segments("cad", _wavy(2000, turns=8.0) * [1.0, 3.0], 100)
    # streamed: a segment every 30 batches (the geometry stays a little ahead of the
    # machine, which sometimes has to slow down for it), else everything at once
    feed = {30 * i: [s] for i, s in enumerate(segs)} if stream else {0: segs}
    runs, new_keep = {}, engine_mod.REPLAN_KEEP
    for keep in (new_keep, np.inf):
        monkeypatch.setattr(engine_mod, "REPLAN_KEEP", keep)
        rec = _Recorder()
        monkeypatch.setattr(plans_mod, "verify", rec)
        engine = Engine(cfg, HeuristicPlanner(margin=1.0))
        batches, looks = _run(engine, feed)
        runs[keep] = (engine, batches, looks, rec)
    engine, batches, looks, rec = runs[new_keep]
    old_engine, old_batches, _, _ = runs[np.inf]
    pos = np.vstack([b.pos for b in batches])
    checker = LimitChecker(m.limits, m.dt)
    checker.feed(pos)
    assert checker.report().ok
    assert engine.replans > 1 and engine.fallbacks == 0 and engine.replan_failures == 0
    # every committed plan was checked (with the published tail) and passed
    committed = [p for p, problem in rec.calls if problem is None]
    assert len(committed) == engine.replans
    assert all(problem is None for _, problem in rec.calls)
    duration, old_duration = len(pos), sum(b.n for b in old_batches)
    # within 4 %, either way: since the heuristic continues its last plan
    # (`heuristic.continuation`), a replan every 0.1 s also mixes layouts along a window
    # (8270 samples here against 8546; before, 8827 against 8622); on the 64 non-long
    # corpus paths a replan every 0.1 s was -4.4 .. +3.9 % (median 0) for 15x the compute
    # (bench/results/corpus_heuristic_replan_every.json)
    assert duration <= 1.04 * old_duration
    if stream:
        assert engine.replans >= len(segs) // 2  # extended as the geometry arrives
    else:
        assert engine.replans < old_engine.replans
        # (and once when the window first reaches the job's end: its exact time left)
        assert sum(end for _, end in looks) == 1
        assert max(look for look, end in looks if not end) <= engine._keep * (1 + 1e-9)
        length = float(np.sum(np.linalg.norm(np.diff(pos, axis=0) * m.path_scale, axis=1)))
        assert engine.replans <= length / (engine.horizon_len - engine._keep) + 3


# --- the geometry a segment and a batch touch ------------------------------------------


def _zigzag_points(n: int = 400, seed: int = 5) -> np.ndarray:
    """Sharp-ish turns a cubic fit overshoots (excursion warnings), then smooth stretches."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(n, 2)) * [4.0, 6.0] + [3.0, 5.0]
    return np.cumsum(steps, axis=0)


@pytest.mark.parametrize("method", ["cubic", "pchip"])
def test_final_path_is_the_live_path_on_its_final_intervals(method):
    """`StreamingFit.final_path()` (what the excursion check measures) is bit for bit the
    live `path()` on [0, final_length]: knots, arc lengths, positions and derivatives."""
    from lookahead.geometry.fits import make_streaming_fit

    rng = np.random.default_rng(3)
    pts = _zigzag_points(300)
    scale = np.array([1.0, 0.5])
    fit = make_streaming_fit(2, scale, method)
    checked = 0
    a = 0
    while a < len(pts):
        b = a + int(rng.integers(1, 40))
        fit.extend(pts[a:b])
        a = b
        final = fit.final_path()
        live = fit.path()
        if final is None:
            assert fit.final_length == 0.0
            continue
        k0 = len(final.breakpoints_u()) - 1
        # the intervals the check measured before: from the live path's arc lengths
        assert k0 == int(np.searchsorted(live.breakpoints_s(), fit.final_length,
                                         side="right") - 1)
        np.testing.assert_array_equal(final.breakpoints_u(), live.breakpoints_u()[:k0 + 1])
        np.testing.assert_array_equal(final.breakpoints_s(), live.breakpoints_s()[:k0 + 1])
        assert final.length == fit.final_length
        u = np.sort(rng.uniform(0.0, final.breakpoints_u()[-1], 200))
        np.testing.assert_array_equal(final.eval_u(u, 3), live.eval_u(u, 3))
        np.testing.assert_array_equal(final.s_of_u(u), live.s_of_u(u))
        checked += 1
    assert checked > 5


def _count_calls(monkeypatch, owner, name: str) -> list[int]:
    calls = [0]
    inner = getattr(owner, name)

    def counted(*args, **kwargs):
        calls[0] += 1
        return inner(*args, **kwargs)

    monkeypatch.setattr(owner, name, counted)
    return calls


def test_segments_are_checked_for_excursions_without_building_the_live_path(monkeypatch):
    """Taking in a segment measures the fit's newly final pieces only: the tail the next
    points change is not solved and integrated per segment (it was, ~3 ms each), and the
    warnings are those of measuring the live path as before."""
    from lookahead.geometry.deviation import interval_excursions as measure
    from lookahead.geometry.streaming import StreamingFit
    from lookahead.stream.assembler import MAX_WARNINGS

    cfg = default_config()
    pts = _zigzag_points(400)
    segs = _segments("zz", pts, 25)
    # the warnings as before: the live path's final intervals after each segment
    fit = StreamingFit(2, np.asarray(cfg.machine.path_scale), "cubic")
    want, checked = [], 0
    for seg in segs[:-1]:
        fit.extend(seg.points)
        live = fit.path()
        k1 = int(np.searchsorted(live.breakpoints_s(), fit.final_length, side="right") - 1)
        if k1 > checked:
            found = measure(live, fit.points(), checked, k1, cfg.planner.tolerance)
            checked = k1
            if found:
                worst = max(found, key=lambda e: e.dev)
                want.append((seg.seq, worst.s_max, worst.dev))
    assert len(want) >= 3
    tails = _count_calls(monkeypatch, StreamingFit, "_tail_pieces")
    engine = Engine(cfg, HeuristicPlanner(margin=1.0))
    for seg in segs[:-1]:
        engine.submit(seg)
    assert tails[0] == 0
    got = [(e.extra["seq"], e.extra["s"], e.extra["deviation"])
           for e in engine.drain_events() if e.type == "warning"]
    assert got == want[:MAX_WARNINGS]


@pytest.mark.parametrize("stream", [False, True])
def test_batches_between_replans_do_not_touch_the_geometry(monkeypatch, stream):
    """A batch whose plan looks ahead more than the keep distance, or ends the finished
    job, decides from the plan alone: no `JobGeometry.path()` (a rebuild of the live path
    after each new segment). It was asked 1.5-3 times a batch. Streamed as the service
    runs it (real time; fast mode also asks each batch whether the plan stops at the end
    of what was sent), batches whose plan the streamed geometry holds back still ask."""
    from lookahead.stream.assembler import JobGeometry

    cfg = default_config()
    segs = _segments("geo", _wavy(2000, turns=8.0) * [1.0, 3.0], 100)
    feed = {30 * i: [s] for i, s in enumerate(segs)} if stream else {0: segs}
    engine = Engine(cfg, HeuristicPlanner(margin=1.0), realtime=stream)
    paths = _count_calls(monkeypatch, JobGeometry, "path")
    batches, _ = _run(engine, feed)
    assert len(batches) > 20 * engine.replans
    if stream:
        assert paths[0] < 0.5 * len(batches), (paths[0], len(batches))
    else:  # per replan: its request and bookkeeping; a few at the job's start and end
        assert paths[0] <= 6 * engine.replans + 20, (paths[0], engine.replans)


def test_per_batch_shortcuts_change_no_batch(monkeypatch):
    """The per-job memos (`settled`, `ends_job`, `end_memo`) and `CommittedPlan.s_at` give
    the batches of deciding everything afresh each batch: streamed geometry, a hold and
    resume, overrides down and up, to the end of the job."""
    from lookahead.protocol import Command

    cfg = default_config()
    segs = _segments("memo", _wavy(1500, turns=6.0) * [1.0, 3.0], 100)
    feed = {25 * i: [s] for i, s in enumerate(segs)}
    commands = {300: "hold", 420: "resume", 700: ("override", 0.6), 900: ("override", 1.0)}

    def run(fresh: bool):
        engine = Engine(cfg, HeuristicPlanner(margin=1.0))
        out = []
        for i in range(100_000):
            for seg in feed.get(i, []):
                engine.submit(seg)
            cmd = commands.get(i)
            if cmd is not None:
                verb, value = (cmd, None) if isinstance(cmd, str) else cmd
                assert engine.command(Command(verb, value)).ok
            job = engine._active
            if fresh and job is not None:
                job.settled = job.ends_job = job.end_memo = None
            batch = engine.next_batch()
            if batch is not None:
                out.append(batch)
                if batch.final:
                    return engine, out
        raise AssertionError("the job did not finish")

    with monkeypatch.context() as mp:
        mp.setattr(CommittedPlan, "s_at", lambda self, k, dt: self.state(k, dt).s)
        ref_engine, ref = run(fresh=True)
    engine, got = run(fresh=False)
    assert engine.replans == ref_engine.replans > 5
    assert len(got) == len(ref)
    for a, b in zip(got, ref, strict=True):
        assert (a.k0, a.final) == (b.k0, b.final)
        for f in ("pos", "vel", "acc"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
