"""`lookahead plan`: plan a whole job offline, check it, report, save and plot it.

Input: a preset (`tube-1450` or `--preset tube-1450`), a points file (CSV with a header of
axis names, or .npy) or a G-code file (.nc/.gcode/.ngc/.tap). Output: a summary on stdout (duration,
compute time, per-axis peaks as a fraction of the limit from the finite-difference checker,
violations); `--out FILE.npz` with pos, vel, acc (K x axes), dt, axes; `--plot FILE.png`.
Exit status 0 when the sampled stream passes the checker, 1 when it does not, 2 on bad input.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path as FilePath

import numpy as np

METHODS = ("heuristic", "lp", "nlp")
_PLANNER_CLASS = {"heuristic": "HeuristicPlanner", "lp": "LPPlanner", "nlp": "NLPPlanner"}
_GCODE_SUFFIXES = {".nc", ".gcode", ".ngc", ".tap", ".g"}


def add_parser(subparsers, name: str = "plan",
               help_text: str = "plan a whole job offline and report/plot it"):
    p = subparsers.add_parser(name, help=help_text, description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--preset", help="winding preset, e.g. tube-1450 or tube-9570")
    src.add_argument("input", nargs="?",
                     help="preset name (as --preset), points file (.csv/.npy) or G-code file")
    p.add_argument("--circuits", default=None,
                   help="preset circuits: a number or 'layer' (default: 1 circuit)")
    p.add_argument("--method", choices=METHODS, default=None,
                   help="planner (default: the config's planner.method)")
    p.add_argument("--config", default=None, help="machine configuration TOML")
    p.add_argument("--fit", choices=("cubic", "pchip"), default=None,
                   help="fit of the point stream (default: the config's planner.fit)")
    p.add_argument("--out", default=None, help="write samples to this .npz")
    p.add_argument("--plot", default=None, help="write a plot to this .png")
    p.add_argument("--progress", action="store_true", help="force the progress bar")
    return p


def load_planner(method: str):
    """The planner class of `method`, imported only when asked for."""
    module = importlib.import_module(f"lookahead.planning.{method}")
    return getattr(module, _PLANNER_CLASS[method])()


def _read_input(args: argparse.Namespace, axes: list[str]) -> tuple[list[str], np.ndarray]:
    from lookahead.geometry.winding import PRESETS, preset_points

    preset = args.preset
    if preset is None and args.input in PRESETS and not FilePath(args.input).exists():
        preset = args.input  # `lookahead plan tube-1450`, as `lookahead publish` takes it
    if preset:
        circuits = args.circuits
        if circuits is not None and circuits != "layer":
            circuits = int(circuits)
        names, points, _ = preset_points(preset, circuits)
        return names, points
    path = FilePath(args.input)
    if path.suffix.lower() in _GCODE_SUFFIXES:
        from lookahead.geometry.gcode import read_gcode

        result = read_gcode(path.read_text(), axes=axes)
        return list(result.axes), result.points
    from lookahead.geometry.files import load_points_file

    return load_points_file(path, axes if path.suffix.lower() == ".npy" else None)


def _drop_repeats(points: np.ndarray) -> np.ndarray:
    """Skip zero-length moves (repeated points)."""
    keep = np.concatenate([[True], np.any(np.diff(points, axis=0) != 0, axis=1)])
    return points[keep]


def _format_fractions(values: list[float]) -> str:
    return " ".join(f"{v:6.3f}" for v in values)


def run(args: argparse.Namespace) -> int:
    from lookahead.checker import LimitChecker
    from lookahead.config import default_config, load_config
    from lookahead.geometry.spline_path import fit_points
    from lookahead.planning.base import PathState, PlanRequest
    from lookahead.progress import Progress
    from lookahead.sampling import sample_profile, sample_times

    try:
        config = load_config(args.config) if args.config else default_config()
        machine = config.machine
        axes, points = _read_input(args, list(machine.axes))
        if list(axes) != list(machine.axes):
            raise ValueError(f"input axes {axes} differ from the machine's {list(machine.axes)}")
        points = _drop_repeats(np.asarray(points, dtype=float))
        if len(points) < 2:
            raise ValueError("the input has fewer than 2 distinct points")
        path = fit_points(points, np.asarray(machine.path_scale), args.fit or config.planner.fit)
    except (OSError, ValueError) as exc:
        print(f"lookahead plan: {exc}", file=sys.stderr)
        return 2
    method = args.method or config.planner.method
    planner = load_planner(method)
    limits, dt = machine.limits, machine.dt
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=dt)
    result = planner.plan(request)

    times = sample_times(result.profile.duration, dt)
    checker = LimitChecker(limits, dt)
    chunks = []
    batch = 20000
    t0 = time.perf_counter()
    with Progress(len(times), "sampling", force=args.progress) as bar:
        for start in range(0, len(times), batch):
            samples = sample_profile(path, result.profile, times[start:start + batch])
            checker.feed(samples.pos)
            chunks.append(samples)
            bar.update(len(samples))
    sample_s = time.perf_counter() - t0
    report = checker.report()
    pos, vel, acc = (np.concatenate([getattr(c, f) for c in chunks]) for f in ("pos", "vel", "acc"))

    duration = result.profile.duration
    print(f"method        {result.method}")
    print(f"points        {len(points)}  path length {path.length:.3f}")
    print(f"duration      {duration:.4f} s  ({len(times)} samples at dt {dt:g} s)")
    print(f"compute       {result.compute_s * 1e3:.1f} ms  (x{duration / result.compute_s:.0f} "
          f"real time); sampling {sample_s * 1e3:.0f} ms")
    print(f"axes          {' '.join(f'{a:>6}' for a in axes)}")
    for kind, name in (("v", "peak |v|"), ("a", "peak |a|"), ("j", "peak |j|")):
        print(f"{name:<13} {_format_fractions(report.peak_fraction[kind])}  (fraction of limit)")
    print(f"violations    {report.violations}" + (f"  first: {report.first}" if report.first
                                                  else ""))
    if args.out:
        np.savez(args.out, pos=pos, vel=vel, acc=acc, dt=dt, axes=np.array(axes))
    if args.plot:
        from lookahead.plotting import plot_plan
        from lookahead.sampling import Samples

        plot_plan(args.plot, result.profile, Samples(pos, vel, acc), limits, dt, axes,
                  title=f"{args.preset or args.input}: {result.method}, {duration:.2f} s")
    return 0 if report.ok else 1
