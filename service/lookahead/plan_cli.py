"""`lookahead plan`: plan a whole job offline, check it, report, save and plot it.

Input: a preset (`tube-1450` or `--preset tube-1450`), a points file (CSV with a header of
axis names, or .npy) or a G-code file (.nc/.gcode/.ngc/.tap). Output: a summary on stdout (duration,
compute time, per-axis peaks as a fraction of the limit from the finite-difference checker,
violations); `--out FILE.npz` with pos, vel, acc (K x axes), dt, axes; `--plot FILE.png`.
Exit status 0 when the sampled stream passes the checker (and no window fell back), 1 when
it does not or the planner fails (one line: the planner, the place on the path as s and the
point index, and the reason), 2 on bad input.
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
    p.add_argument("--fit", choices=("cubic", "pchip", "linear", "smooth"), default=None,
                   help="fit of the point stream (default: the config's planner.fit; for "
                        "G-code the G-code fit, smooth)")
    p.add_argument("--tolerance", type=float, default=None,
                   help="how far fits linear/smooth may leave the points' polyline, path "
                        "units (default: the config's planner.tolerance; G-code G64 P/G61 "
                        "override it per move)")
    p.add_argument("--dialect", choices=("marlin", "rs274"), default=None,
                   help="G-code dialect (default: the config's gcode.dialect): what F "
                        "measures and whether G0 takes it")
    p.add_argument("--ignore-letters", default="", metavar="LETTERS",
                   help="G-code axis letters to drop, e.g. B (with the config's gcode.ignore)")
    p.add_argument("--out", default=None, help="write samples to this .npz")
    p.add_argument("--plot", default=None, help="write a plot to this .png")
    p.add_argument("--progress", action="store_true", help="force the progress bar")
    return p


def load_planner(method: str):
    """The planner class of `method`, imported only when asked for."""
    module = importlib.import_module(f"lookahead.planning.{method}")
    return getattr(module, _PLANNER_CLASS[method])()


def _read_input(args: argparse.Namespace, config
                ) -> tuple[list[str], np.ndarray, np.ndarray | None, float | None,
                           np.ndarray | None]:
    """(axes, points, per-point tolerance from G-code or None, the G-code program's own
    time estimate in s or None, per-point feed caps from G-code (path units/s, NaN = none;
    each caps the move that ends at its point) or None)."""
    axes = list(config.machine.axes)
    from lookahead.geometry.winding import PRESETS, preset_points

    preset = args.preset
    if preset is None and args.input in PRESETS and not FilePath(args.input).exists():
        preset = args.input  # `lookahead plan tube-1450`, as `lookahead publish` takes it
    if preset:
        circuits = args.circuits
        if circuits is not None and circuits != "layer":
            circuits = int(circuits)
        names, points, _ = preset_points(preset, circuits)
        return names, points, None, None, None
    path = FilePath(args.input)
    if path.suffix.lower() in _GCODE_SUFFIXES:
        from lookahead.geometry.gcode import read_gcode

        result = read_gcode(path.read_text(), **config.gcode_options(
            ignore=args.ignore_letters, dialect=args.dialect))
        for letter, count in (result.ignored or {}).items():
            print(f"lookahead plan: warning: dropped {count} {letter} word(s): the machine has "
                  f"no drive for letter {letter} (gcode.ignore / --ignore-letters)",
                  file=sys.stderr)
        return (list(result.axes), result.points, result.tolerance, result.programmed_time_s,
                result.feed)
    from lookahead.geometry.files import load_points_file

    names, points = load_points_file(path, axes if path.suffix.lower() == ".npy" else None)
    return names, points, None, None, None


def _feed_cap(points: np.ndarray, feeds: np.ndarray | None, scale: np.ndarray,
              length: float):
    """The G-code feed caps as a FeedCap over s, or None. A point's cap holds on the move
    that ends there; the moves' places in s are their cumulative chord lengths in the path
    metric, scaled to the fitted path's length (the fits stay within their tolerance of the
    polyline, so a cap moves by at most about that)."""
    from lookahead.planning.base import FeedCap

    if feeds is None or not np.any(np.isfinite(feeds[1:])):
        return None
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0) * scale,
                                                          axis=1))])
    s_at = chord * (length / chord[-1])
    caps = np.where(np.isfinite(feeds[1:]), feeds[1:], np.inf)
    change = np.flatnonzero(caps[1:] != caps[:-1]) + 1
    starts = np.concatenate([[0], change])
    breaks = np.concatenate([s_at[starts], [length]])
    values = caps[starts]
    values = np.where(np.isfinite(values), values, 1e12)  # no cap: far above any feed
    return FeedCap(breaks, values)


def _drop_repeats(points: np.ndarray) -> np.ndarray:
    """Skip zero-length moves (repeated points): the rows kept (a mask)."""
    return np.concatenate([[True], np.any(np.diff(points, axis=0) != 0, axis=1)])


def _format_fractions(values: list[float]) -> str:
    return " ".join(f"{v:6.3f}" for v in values)


def run(args: argparse.Namespace) -> int:
    from lookahead.checker import LimitChecker
    from lookahead.config import default_config, load_config
    from lookahead.geometry.deviation import excursions, polyline_distance
    from lookahead.geometry.fits import TOLERANCE_FITS, fit_path
    from lookahead.geometry.gcode import GCODE_FIT
    from lookahead.geometry.polyline import check_tolerance
    from lookahead.geometry.spline_path import fit_points
    from lookahead.planning.base import PathState, PlanningError, PlanRequest
    from lookahead.planning.place import describe_place, failure_s
    from lookahead.progress import Progress
    from lookahead.sampling import sample_profile, sample_times

    try:
        config = load_config(args.config) if args.config else default_config()
        machine = config.machine
        axes, points, point_tol, program_time, feeds = _read_input(args, config)
        if list(axes) != list(machine.axes):
            raise ValueError(f"input axes {axes} differ from the machine's {list(machine.axes)}")
        points = np.asarray(points, dtype=float)
        keep = _drop_repeats(points)
        points = points[keep]
        point_tol = None if point_tol is None else point_tol[keep]
        feeds = None if feeds is None else feeds[keep]
        if len(points) < 2:
            raise ValueError("the input has fewer than 2 distinct points")
        fit = args.fit or (GCODE_FIT if point_tol is not None else config.planner.fit)
        tolerance = config.planner.tolerance if args.tolerance is None else check_tolerance(
            args.tolerance, "--tolerance")
        scale = np.asarray(machine.path_scale)
        if fit in TOLERANCE_FITS:
            path = fit_path(points, scale, fit, point_tol, default_tolerance=tolerance)
        else:
            path = fit_points(points, scale, fit)
    except (OSError, ValueError) as exc:
        print(f"lookahead plan: {exc}", file=sys.stderr)
        return 2
    method = args.method or config.planner.method
    planner = load_planner(method)
    limits, dt = machine.limits, machine.dt
    request = PlanRequest(path, limits, PathState(0.0), path.length, dt=dt,
                          feed_cap=_feed_cap(points, feeds, scale, path.length))
    try:
        result = planner.plan(request)
    except (PlanningError, ValueError, RuntimeError, ArithmeticError) as exc:
        # a planning failure is one line, never a traceback (issue 13)
        s_fail = failure_s(exc, request.start.s)
        print(f"lookahead plan: {getattr(planner, 'name', method)} failed at "
              f"{describe_place(path, s_fail)} of {path.length:.6g}: {exc}", file=sys.stderr)
        return 1

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
    if program_time:
        print(f"program says  {program_time:.4f} s at its F words (the CAM's estimate; "
              f"planned / program {duration / program_time:.3f})")
    print(f"compute       {result.compute_s * 1e3:.1f} ms  (x{duration / result.compute_s:.0f} "
          f"real time); sampling {sample_s * 1e3:.0f} ms")
    print(f"axes          {' '.join(f'{a:>6}' for a in axes)}")
    for kind, name in (("v", "peak |v|"), ("a", "peak |a|"), ("j", "peak |j|")):
        print(f"{name:<13} {_format_fractions(report.peak_fraction[kind])}  (fraction of limit)")
    print(f"violations    {report.violations}" + (f"  first: {report.first}" if report.first
                                                  else ""))
    dev = polyline_distance(pos, points, scale)
    worst = int(np.argmax(dev))
    print(f"deviation     {dev[worst]:.6g} path units from the programmed polyline (largest "
          f"over the samples, at t = {worst * dt:.4f} s; fit {fit}"
          + (f", tolerance {tolerance:g})" if fit in TOLERANCE_FITS else ")"))
    if fit not in TOLERANCE_FITS:
        found = excursions(path, points, tolerance)
        if found:
            far = max(found, key=lambda e: e.dev)
            print(f"excursions    {len(found)} stretch(es) of the {fit} fit leave the polyline "
                  f"by more than {tolerance:g}; worst {far.dev:.6g} at s = {far.s_max:.6g} "
                  "(fit linear or smooth follows it)")
    fallbacks = int(result.info.get("fallbacks", 0) or 0)
    print(f"fallbacks     {fallbacks}" + ("  (windows the planner could not make)"
                                          if fallbacks else ""))
    if args.out:
        np.savez(args.out, pos=pos, vel=vel, acc=acc, dt=dt, axes=np.array(axes))
    if args.plot:
        from lookahead.plotting import plot_plan
        from lookahead.sampling import Samples

        plot_plan(args.plot, result.profile, Samples(pos, vel, acc), limits, dt, axes,
                  title=f"{args.preset or args.input}: {result.method}, {duration:.2f} s")
    return 0 if report.ok and fallbacks == 0 else 1
