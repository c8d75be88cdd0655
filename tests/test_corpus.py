"""The path corpus (bench/corpus): deterministic, valid protocol segments, unique names, a
small fast subset, every family, and the ranges issue 13 asks for."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bench.corpus import FAMILIES, load_corpus
from bench.corpus.winding import TURNS

from lookahead.protocol import JOB_ID_RE, Segment


@pytest.fixture(scope="module")
def everything():
    return load_corpus("all")


@pytest.fixture(scope="module")
def fast():
    return load_corpus("fast")


def test_sizes_and_families(everything, fast) -> None:
    assert len(everything) >= 50
    assert 10 <= len(fast) <= 16
    assert {p.family for p in everything} == set(FAMILIES)
    assert {p.family for p in fast} == set(FAMILIES)
    assert all(p.fast for p in fast)
    assert {p.name for p in fast} <= {p.name for p in everything}


def test_names_unique_and_job_ids(everything) -> None:
    names = [p.name for p in everything]
    assert len(set(names)) == len(names)
    assert all(JOB_ID_RE.match(n) for n in names)


def test_fast_subset_is_deterministic_and_encodes(fast) -> None:
    again = {p.name: p for p in load_corpus("fast")}
    for p in fast:
        segs = p.segments
        assert segs and segs[-1].last and not any(s.last for s in segs[:-1])
        assert [s.seq for s in segs] == list(range(len(segs)))
        other = again[p.name].segments
        assert len(other) == len(segs)
        axes = tuple(p.config.machine.axes)
        for a, b in zip(segs, other, strict=True):
            payload = a.encode()
            assert payload == b.encode()
            back = Segment.decode(payload, axes)
            assert back.job == p.name and back.kind == a.kind
            if a.kind == "points":
                assert np.array_equal(back.points, a.points)
                assert len(a.points) <= 500
            else:
                assert np.array_equal(back.ctrl, a.ctrl)


def test_fast_paths_fit_as_the_service_does(fast) -> None:
    for p in fast:
        path = p.path()
        assert path.naxes == p.config.machine.naxes
        assert path.length > 0
        first = p.segments[0].points[0] if p.segments[0].kind == "points" else \
            p.segments[0].ctrl[0]
        start = path.eval_s(np.array([0.0]), order=0)[0, 0]
        assert np.allclose(start, first, atol=1e-9)


def test_winding_ranges(everything) -> None:
    wind = [p for p in everything if p.family == "winding"]
    radii = [p.params["radius"] for p in wind]
    alphas = [a for p in wind for a in np.atleast_1d(p.params["alpha_deg"])]
    spacings = [x for p in wind for x in np.atleast_1d(p.params["spacing"])]
    assert min(radii) <= 25 and max(radii) >= 500
    assert min(alphas) <= 5 and max(alphas) >= 85
    assert min(spacings) <= 0.2 and max(spacings) >= 20
    kinds = {p.params["kind"] for p in wind}
    assert {"helical", "hoop", "polar", "dome", "cone", "layers"} <= kinds
    assert {p.params["turn"] for p in wind if "turn" in p.params} == set(TURNS)
    assert sum(p.long for p in wind) >= 1


def test_helical_points_have_the_angle_and_spacing_they_claim(everything) -> None:
    p = next(p for p in everything if p.name == "w-hel-R40-a60-septic-1mm")
    pts = np.vstack([s.points for s in p.segments])
    r, alpha, h = p.params["radius"], p.params["alpha_deg"], p.params["spacing"]
    d = np.diff(pts, axis=0)
    fibre = np.hypot(d[:, 0], np.radians(d[:, 1]) * r)
    assert np.median(fibre) == pytest.approx(h, rel=1e-3)
    assert fibre.max() <= h * (1 + 1e-4)  # arc length on a dense polyline
    angle = np.degrees(np.arctan2(np.radians(d[:, 1]) * r, np.abs(d[:, 0])))
    on_alpha = np.abs(angle - alpha) < 1e-6  # the constant-angle strokes
    assert 0.8 < np.mean(on_alpha) < 1.0  # the rest: turnarounds
    assert np.all(d[:, 1] > 0)  # the mandrel only turns forward


def test_issue_examples_are_there(everything) -> None:
    by = {p.name: p for p in everything}
    tube = by["w-issue-tube1450-R100-a45-sine-2mm"]
    assert (tube.params["length"], tube.params["radius"], tube.params["alpha_deg"],
            tube.params["turn"], tube.params["spacing"]) == (1450, 100, 45, "sine", 2.0)
    assert by["w-issue-tube800-R60-a70-3pass"].params["strokes"] == 3
    assert by["w-issue-tube9570-R150-a55-5mm"].params["spacing"] == 5.0
    bf = by["n-butterfly"]
    m = bf.config.machine
    assert (m.vmax, m.amax, m.jmax) == ((150.0,) * 2, (1500.0,) * 2, (20000.0,) * 2)
    seg = bf.segments[0]
    assert seg.kind == "nurbs" and len(seg.ctrl) == 51 and seg.degree == 3
    four = np.vstack([s.points for s in by["c-fourier-xc-3000pts"].segments])
    assert len(four) == 3000
    dc = np.diff(four[:, 1])
    assert 0.6 < np.mean(dc > 0) < 1.0  # mostly increasing, with reversals


def test_cnc_covers_scales_corners_and_short_paths(everything) -> None:
    cnc = [p for p in everything if p.family == "cnc"]
    naxes = {p.config.machine.naxes for p in cnc}
    assert {2, 3, 4, 5, 6} <= naxes
    spans = [max(p.config.machine.vmax) / min(p.config.machine.vmax) for p in cnc]
    assert max(spans) >= 1e5  # limits of very different scales on one machine
    corners = next(p for p in cnc if p.name == "c-corners-bspline-2d")
    assert all(s.kind == "bspline" for s in corners.segments)
    assert len(corners.path().corners_s()) == len(corners.segments) - 1
    short = [p for p in cnc if p.params.get("kind") == "short"]
    assert len(short) >= 2 and all(p.path().length < 1.0 for p in short)


def test_cam_family(everything) -> None:
    cam = [p for p in everything if p.family == "cam"]
    assert len(cam) >= 4 and any(p.long for p in cam)
    small = next(p for p in cam if p.fast and p.params["kind"] in ("fiberpath",
                                                                   "fiberpath-style"))
    pts = np.vstack([s.points for s in small.segments])
    assert pts.shape[1] == 2
    assert np.all(np.diff(pts[:, 1]) >= 0)  # C unwrapped across G92 resets


def test_long_paths_are_marked(everything) -> None:
    long = [p for p in everything if p.long]
    assert len(long) >= 2
    walk = next(p for p in long if p.name.startswith("c-long"))
    assert walk.npoints >= 100_000
    assert {p.name for p in load_corpus("all", skip_long=True)} == \
        {p.name for p in everything if not p.long}


def test_pattern_filter() -> None:
    names = [p.name for p in load_corpus("all", pattern="n-*")]
    assert names and all(n.startswith("n-") for n in names)
    with pytest.raises(ValueError):
        load_corpus("most")


@pytest.mark.slow
def test_every_path_encodes_and_fits(everything) -> None:
    for p in everything:
        axes = tuple(p.config.machine.axes)
        for s in p.segments:
            assert Segment.decode(s.encode(), axes).seq == s.seq
        assert math.isfinite(p.path().length)


def test_corpus_bench_runs_end_to_end(tmp_path) -> None:
    import json

    from bench import corpus_bench

    out = tmp_path / "corpus.json"
    rc = corpus_bench.main(["--subset", "all", "--paths", "c-short-xy-0p5mm",
                            "--methods", "heuristic,lp,engine-lp,reference", "--workers", "1",
                            "--out", str(out), "--no-plot", "--task-timeout", "120"])
    assert rc == 0
    doc = json.loads(out.read_text())
    entry = doc["paths"]["c-short-xy-0p5mm"]
    assert set(entry["methods"]) == {"heuristic", "lp", "engine-lp", "reference"}
    assert doc["meta"]["git"]["head"] and doc["meta"]["git"]["time_utc"]
    bound = entry["bound_s"]
    assert bound > 0
    ref = entry["methods"]["reference"]
    assert ref["violations"] == 0 and ref["winding_s"] >= bound * 0.999
    usable = [r["winding_s"] for r in entry["methods"].values() if corpus_bench.usable(r)]
    assert entry["best_s"] == min(usable)
    for row in entry["methods"].values():
        assert "winding_s" in row or "error" in row
        if "winding_s" in row:
            assert row["ratio_best"] >= 1.0 - 1e-12
    engine = entry["methods"]["engine-lp"]
    assert {"fallbacks", "replan_failures", "replan_ms_p99", "x_realtime"} <= set(engine)
    # the windowed plan against the whole job in samples: (samples - 1) dt of each
    whole = entry["methods"]["lp"]
    dt = 0.001
    assert whole["winding_s"] <= whole["winding_sampled_s"] < whole["winding_s"] + dt
    assert engine["ratio_whole"] == engine["winding_s"] / whole["winding_sampled_s"]
    assert "ratio_whole" not in whole
    assert set(doc["summary"]) == {"heuristic", "lp", "engine-lp", "reference"}
    assert doc["summary"]["engine-lp"]["ratio_whole"]["worst"] == engine["ratio_whole"]


def test_reference_quintic_hermite_matches_values_slopes_and_curvatures() -> None:
    from bench.reference import quintic_hermite

    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(0.1, 2.0, size=9))
    p, v, a = rng.normal(size=(3, 9))
    pp = quintic_hermite(t, p, v, a)
    for nu, want in ((0, p), (1, v), (2, a)):
        d = pp.derivative(nu) if nu else pp
        assert np.allclose(d(t), want, atol=1e-9)  # the right-hand pieces' starts
        # each piece's own end (the left side of every breakpoint) too: C2 there
        ends = [np.polyval(d.c[:, i], t[i + 1] - t[i]) for i in range(t.size - 1)]
        assert np.allclose(ends, want[1:], atol=1e-8)
