"""How far last-bit differences grow through the engine: the measurement that
`lookahead_clients.replay.FOREIGN_TOLERANCE` is derived from.

Another CPU runs other SIMD kernels (numpy's OpenBLAS, scipy, HiGHS), so the same software
rounds differently in the last bits. We cannot run another CPU here, so we reproduce the
effect: every input coordinate of a recording is multiplied by 1 +- REL (random signs,
several seeds) and the recording is replayed; the largest |difference| of pos, vel and acc
against the unperturbed setpoints is how far such a difference grows through fit, planner,
replans and sampler. REL is 1 ulp (2^-52) and 16 ulps.

Two regimes show up. Smooth: the differences grow in proportion to REL (the LP: ~2e-8 mm
of position and ~6e-6 mm/s^2 of acceleration per ulp on tube-1450). Flipped: a planning
decision (a verification at its limit, a repair round, a bisection step) goes the other way
and the streams part by millimetres or by a sample (the heuristic on tube-9570, every
seed). The tolerance is derived from the smooth runs; a flipped run is what replay reports
as "diverged" on another CPU.

Recordings: the golden file of the tests (heuristic, recorded by a real service) and fresh
in-process recordings (`record_engine`) of both presets with both planners.

    .venv/bin/python bench/replay_tolerance.py [--out bench/results/replay_tolerance.json]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
import time
import tomllib

import numpy as np

from lookahead.config import build_config, default_config
from lookahead_clients.job_source import load_job, make_segments
from lookahead_clients.recording import floating_point_environment, read_recording
from lookahead_clients.replay import FOREIGN_TOLERANCE, record_engine, replay

HERE = os.path.dirname(os.path.abspath(__file__))
GOLDEN = os.path.join(HERE, "..", "tests", "data", "golden-short.rec")
#: relative input perturbations, in ulps of 1.0 (2^-52)
ULPS = (1, 16)
SEEDS = (0, 1, 2, 3)
#: the REL whose smooth worst case the tolerance is derived from: 1 ulp of every input, more
#: than another CPU changes (only its BLAS, LAPACK, HiGHS and SIMD transcendental kernels
#: round differently, and each by an ulp or so)
BASIS_ULPS = 1
SAFETY = 10.0
#: a run whose positions part by more than this (mm or deg), or whose batches differ in
#: length, flipped a planning decision: no smooth growth gets near it (LP: 3e-7 at 16 ulps)
FLIP_POS = 1e-3


def fresh_recording(preset: str, method: str):
    """An in-process recording of one circuit of `preset` planned with `method`."""
    from dataclasses import replace

    cfg = default_config()
    cfg = replace(cfg, planner=replace(cfg.planner, method=method))
    job = load_job(preset, list(cfg.machine.axes))
    segs = make_segments(f"{preset}-{method}", list(cfg.machine.axes), job.points, chunk=200)
    buf = io.BytesIO()
    record_engine(cfg, segs, buf, feed_every=20)
    path = os.path.join("/tmp", f"replay-tolerance-{preset}-{method}.rec")
    with open(path, "wb") as fh:
        fh.write(buf.getvalue())
    return path


def per_quantity(rec, cfg, rel: float, seed: int) -> dict[str, float]:
    """Largest |difference| of pos, vel and acc of `rec` replayed with inputs perturbed."""
    import lookahead_clients.replay as rp

    worst = {"pos": 0.0, "vel": 0.0, "acc": 0.0, "header_mismatches": 0}
    names = iter(())
    original = rp._max_diff

    def spy(a, b):
        nonlocal names
        try:
            name = next(names)
        except StopIteration:
            names = iter(("pos", "vel", "acc"))
            name = next(names)
        d = original(a, b)
        if np.isfinite(d):  # inf: another shape (the job ended a sample earlier or later)
            worst[name] = max(worst[name], d)
        return d

    rp._max_diff = spy  # replay compares pos, vel, acc in this order for every batch
    try:
        res = replay(rec, cfg, tolerance=float("inf"), perturb=rel, seed=seed)
    finally:
        rp._max_diff = original
    worst["header_mismatches"] = res.batches - res.matched  # n or final differ (tolerance inf)
    worst["flipped"] = worst["header_mismatches"] > 0 or worst["pos"] > FLIP_POS
    return worst


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(HERE, "results", "replay_tolerance.json"))
    args = ap.parse_args()
    recordings = {"golden-short (heuristic, real service)": GOLDEN}
    for preset in ("tube-1450", "tube-9570"):
        for method in ("heuristic", "lp"):
            print(f"recording {preset} {method} ...", file=sys.stderr)
            recordings[f"{preset} ({method}, in-process)"] = fresh_recording(preset, method)
    rows = []
    t0 = time.perf_counter()
    for name, path in recordings.items():
        rec = read_recording(path)
        cfg = build_config(tomllib.loads(rec.header["config_toml"]))
        exact = replay(rec, cfg)
        for ulps in ULPS:
            rel = ulps * 2.0 ** -52
            for seed in SEEDS:
                row = per_quantity(rec, cfg, rel, seed)
                rows.append({"recording": name, "ulps": ulps, "seed": seed, **row,
                             "unperturbed_identical": exact.identical})
                print(f"{name:42s} {ulps:3d} ulps seed {seed}  pos {row['pos']:.2e}  vel "
                      f"{row['vel']:.2e}  acc {row['acc']:.2e}"
                      f"{'  FLIPPED' if row['flipped'] else ''}", file=sys.stderr)
    smooth = [r for r in rows if r["ulps"] == BASIS_ULPS and not r["flipped"]]
    basis = max(max(r["pos"], r["vel"], r["acc"]) for r in smooth)
    derived = 10.0 ** np.ceil(np.log10(basis * SAFETY))
    flips = {name: sum(r["flipped"] for r in rows if r["recording"] == name and
                       r["ulps"] == BASIS_ULPS) for name in recordings}
    out = {"fp_env": floating_point_environment(), "ulps": ULPS, "seeds": SEEDS,
           "basis_ulps": BASIS_ULPS, "safety": SAFETY, "worst_smooth_at_basis": basis,
           "flipped_runs_at_basis": flips, "flip_pos": FLIP_POS,
           "derived_tolerance": derived, "FOREIGN_TOLERANCE": FOREIGN_TOLERANCE,
           "seconds": time.perf_counter() - t0, "rows": rows}
    with open(args.out, "w") as fh:
        json.dump(out, fh, indent=1)
    print(f"worst smooth |difference| at {BASIS_ULPS} ulp(s): {basis:.3g}; x{SAFETY:g} "
          f"rounded up: {derived:g}; FOREIGN_TOLERANCE = {FOREIGN_TOLERANCE:g}; flipped runs "
          f"at {BASIS_ULPS} ulp(s) of {len(SEEDS)}: {flips}")
    return 0 if derived <= FOREIGN_TOLERANCE else 1


if __name__ == "__main__":
    sys.exit(main())
