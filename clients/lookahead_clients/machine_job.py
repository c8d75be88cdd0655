"""What the simulated winder does with one job's setpoint batches, without any bus.

`JobMonitor` takes the batches of one job in arrival order (with their arrival time on a
monotonic clock, seconds) and:
- checks every commanded position with the independent finite-difference checker;
- counts sequence gaps (a batch `seq` or `k0` other than the next expected one);
- in real time, counts underruns: batches that arrive after their first sample was due
  (sample k is due at t0 + buffer_s + k*dt, t0 = arrival of the job's first batch);
- runs the drives (`PositionServo`) and measures the following error per axis (axis units);
- measures the fibre angle laid on each traverse against the programmed one (`fibre`).
`report()` returns the `NS/machine/report` map (plain types).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lookahead.checker import LimitChecker
from lookahead.limits import AxisLimits
from lookahead.protocol import SetpointBatch
from lookahead_clients.fibre import angle_errors, radius_from_path_scale, traverses
from lookahead_clients.servo import PositionServo, ServoTuning


@dataclass(frozen=True)
class MachineModel:
    """The simulated machine: axes, limits, path_scale (for R), sample time (s)."""

    axes: tuple[str, ...]
    limits: AxisLimits
    path_scale: tuple[float, ...]
    dt: float
    tuning: ServoTuning = field(default_factory=ServoTuning)

    @property
    def radius(self) -> float | None:
        """Mandrel radius (mm) if the machine has X and C axes, else None."""
        if "X" in self.axes and "C" in self.axes:
            return radius_from_path_scale(self.path_scale[self.axes.index("C")])
        return None


class JobMonitor:
    """The winder's view of one job (see module docstring)."""

    def __init__(self, machine: MachineModel, job: str, realtime: bool,
                 buffer_s: float = 0.0) -> None:
        self.machine = machine
        self.job = job
        self.realtime = realtime
        self.buffer_s = buffer_s
        self.checker = LimitChecker(machine.limits, machine.dt)
        self.servo = PositionServo(machine.limits.amax, machine.dt, machine.tuning)
        self.gaps = 0
        self.underruns = 0
        self.final = False
        self.fault: str | None = None
        #: window plans the service's configured planner could not make (its job_finished
        #: event's `fallbacks`; None: not known). A fallback is a failure (issue 13).
        self.fallbacks: int | None = None
        #: replans the service dropped because they were late (batches' `dropped`): the
        #: plan in force went on, an unplanned slowdown instead of an underrun
        self.late_replans = 0
        self._t0: float | None = None
        self.last_arrival = 0.0
        #: largest (arrival - due time) of a batch's first sample, s (< 0: all early)
        self.max_lateness_s = -float("inf")
        self._next_seq = 0
        self._next_k = 0
        self._pos_cmd: list[np.ndarray] = []
        self._vel_cmd: list[np.ndarray] = []
        self._pos_act: list[np.ndarray] = []
        self._vel_act: list[np.ndarray] = []

    @property
    def samples(self) -> int:
        return self._next_k

    def add(self, batch: SetpointBatch, arrival: float) -> None:
        """Execute one batch that arrived at `arrival` (monotonic seconds)."""
        self.last_arrival = arrival
        if batch.axes != self.machine.axes:
            self.fault = self.fault or (f"setpoint axes {list(batch.axes)} differ from the "
                                        f"machine's {list(self.machine.axes)}")
            return
        if batch.dt != self.machine.dt:
            self.fault = self.fault or (f"setpoint dt {batch.dt} differs from the machine's "
                                        f"{self.machine.dt}")
            return
        if self._t0 is None:
            self._t0 = arrival
            self.servo.reset(batch.pos[0] if batch.n else np.zeros(len(self.machine.axes)))
        if batch.seq != self._next_seq or batch.k0 != self._next_k:
            self.gaps += 1
        self._next_seq = batch.seq + 1
        self._next_k = batch.k0 + batch.n
        lateness = arrival - (self._t0 + self.buffer_s + batch.k0 * batch.dt)
        self.max_lateness_s = max(self.max_lateness_s, lateness)
        if self.realtime and lateness > 0:
            self.underruns += 1
        self.final = self.final or batch.final
        self.late_replans += len(batch.dropped)
        if batch.n == 0:
            return
        self.checker.feed(batch.pos)
        pos_act, vel_act = self.servo.run(batch.pos, batch.vel, batch.acc)
        self._pos_cmd.append(np.array(batch.pos))
        self._vel_cmd.append(np.array(batch.vel))
        self._pos_act.append(pos_act)
        self._vel_act.append(vel_act)

    def arrays(self) -> dict[str, np.ndarray]:
        """Commanded and actual positions and velocities, each (samples, naxes)."""
        naxes = len(self.machine.axes)

        def cat(parts: list[np.ndarray]) -> np.ndarray:
            return np.concatenate(parts) if parts else np.zeros((0, naxes))

        return {"pos_cmd": cat(self._pos_cmd), "vel_cmd": cat(self._vel_cmd),
                "pos_act": cat(self._pos_act), "vel_act": cat(self._vel_act)}

    def report(self) -> dict:
        """The NS/machine/report map of this job (plain types)."""
        check = self.checker.report()
        arr = self.arrays()
        following = np.max(np.abs(arr["pos_cmd"] - arr["pos_act"]), axis=0) \
            if len(arr["pos_cmd"]) else np.zeros(len(self.machine.axes))
        strokes, errors = [], np.zeros(0)
        radius = self.machine.radius
        if radius is not None and len(arr["vel_cmd"]):
            ix, ic = self.machine.axes.index("X"), self.machine.axes.index("C")
            strokes = traverses(arr["vel_cmd"], arr["vel_act"], radius, x_axis=ix, c_axis=ic)
            errors = angle_errors(arr["vel_cmd"], arr["vel_act"], radius, strokes, ix, ic)
        fault = self.fault
        if fault is None and not self.final:
            fault = "the job ended without a final batch"
        clean = (check.ok and self.gaps == 0 and self.underruns == 0 and fault is None
                 and not self.fallbacks and not self.late_replans)
        return {
            "v": 1,
            "job": self.job,
            "axes": list(self.machine.axes),
            "samples": self.samples,
            "duration_s": max(self.samples - 1, 0) * self.machine.dt,
            "violations": check.violations,
            "counts": check.counts,
            "peak_fraction": check.peak_fraction,
            "first_violation": None if check.first is None else check.first._asdict(),
            "gaps": self.gaps,
            "underruns": self.underruns,
            "realtime": self.realtime,
            "max_lateness_s": self.max_lateness_s if self.realtime and self.samples else None,
            "max_following_error": [float(f) for f in following],
            "saturated_samples": self.servo.saturated,
            "radius_mm": radius,
            "traverses": [t.to_dict() for t in strokes],
            "fibre_angle_error_max": float(errors.max()) if errors.size else 0.0,
            "fibre_angle_error_mean": float(errors.mean()) if errors.size else 0.0,
            "fault": fault,
            "fallbacks": self.fallbacks,
            "late_replans": self.late_replans,
            "clean": bool(clean),
        }


def summary(report: dict) -> str:
    """A few human lines about a job report."""
    axes = report["axes"]
    kinds = {"v": "velocity", "a": "acceleration", "j": "jerk"}
    lines = [f"job {report['job']}: {'CLEAN' if report['clean'] else 'NOT CLEAN'}, "
             f"winding time {report['duration_s']:.3f} s ({report['samples']} samples)"]
    for kind, label in kinds.items():
        peaks = ", ".join(f"{a} {100 * f:.1f}%" for a, f in
                          zip(axes, report["peak_fraction"][kind], strict=True))
        counts = sum(report["counts"][kind])
        lines.append(f"  peak {label:12s} {peaks}  (violations: {counts})")
    fe = ", ".join(f"{a} {e:.4g}" for a, e in zip(axes, report["max_following_error"],
                                                   strict=True))
    late = report.get("max_lateness_s")
    late_text = "" if late is None else f" (latest batch {1000 * late:+.1f} ms vs due)"
    lines.append(f"  max following error {fe}; gaps {report['gaps']}, "
                 f"underruns {report['underruns']}{late_text}")
    fallbacks = report.get("fallbacks")
    lines.append("  planner fallbacks " + ("unknown" if fallbacks is None else str(fallbacks))
                 + f", late replans dropped {report.get('late_replans', 0)}")
    lines.append(f"  fibre angle error on {len(report['traverses'])} traverses: max "
                 f"{report['fibre_angle_error_max']:.4f} deg, mean "
                 f"{report['fibre_angle_error_mean']:.4f} deg")
    if report["first_violation"]:
        fv = report["first_violation"]
        lines.append(f"  first violation at sample {fv['k']}: axis {axes[fv['axis']]} "
                     f"{kinds[fv['kind']]} {fv['value']:.6g} > {fv['limit']:.6g}")
    if report["fault"]:
        lines.append(f"  FAULT: {report['fault']}")
    return "\n".join(lines)
