"""What the monitor knows about one machine (namespace NS), fed by the bus side, read by the
web side. No zenoh here: `on_*` methods take decoded messages, `snapshot` returns plain
JSON-ready data. Every method takes the view's lock briefly; nothing here waits for a
browser.

Progress and time (what they are based on, shown on the page):
- `progress`: fraction of the programmed path's length (the segments seen on NS/segments,
  `path_view`) up to the commanded position of the last setpoint received;
- `elapsed_s`: k * dt of the status' last published sample (job time);
- `planned_ahead_s`: the status' `horizon_s`, the service's committed plan from that sample
  to where it comes to rest (the end of the path once the last window reaches it);
- `remaining_s`: the status' `remaining_s` while its `plan_complete` is true (the plan
  reaches the job's end: the exact planned motion time left at the current override), else
  None (the page then shows `planned_ahead_s` and that the end is not planned yet);
- `duration_s`: the job's duration from its `job_finished` event, once it has ended.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import asdict, dataclass

import numpy as np

from lookahead.protocol import Event, Segment, SetpointBatch, Status
from lookahead_clients.monitor.chart import ChartBinner
from lookahead_clients.monitor.path_view import ProgrammedPath

#: events kept per machine for a browser that connects later
EVENT_LOG = 200
#: how long after the monitor subscribed an absent planner token means "no service" (s):
#: the liveliness query with history answers within this on loopback
NO_SERVICE_AFTER_S = 2.0
#: a status older than this (s, monitor clock) is shown as stale (the service publishes at
#: status_hz, 10 Hz by default, at least 5 Hz by the protocol)
STATUS_STALE_S = 1.0
#: programmed paths kept (the running job and the last finished ones)
PATHS_KEPT = 3
#: locate the machine on the path every this many samples (50 ms at dt = 1 ms: 25 mm at
#: 500 mm/s, well inside the forward search window of `ProgrammedPath.locate`)
LOCATE_EVERY = 50


@dataclass(frozen=True)
class MachineSpec:
    """A machine's static description (from its configuration): id, NS, axes, units, limits
    (axis units per s, s^2, s^3), path_scale, dt (s)."""

    id: str
    ns: str
    axes: tuple[str, ...]
    units: tuple[str, ...]
    vmax: tuple[float, ...]
    amax: tuple[float, ...]
    jmax: tuple[float, ...]
    path_scale: tuple[float, ...]
    dt: float

    def to_json(self) -> dict:
        return asdict(self)


class MachineView:
    """Live state of one machine (see module docstring)."""

    def __init__(self, spec: MachineSpec) -> None:
        self.spec = spec
        self.lock = threading.Lock()
        self.chart = ChartBinner(spec.vmax, spec.amax, spec.jmax, spec.path_scale, spec.dt)
        self.started = time.monotonic()
        self.planner_alive: bool | None = None
        self.machine_alive: bool | None = None
        self.status: dict | None = None
        self.status_t = 0.0
        self.events: deque[dict] = deque(maxlen=EVENT_LOG)
        self.event_id = 0
        self.paths: dict[str, ProgrammedPath] = {}
        self.job: str | None = None  # job of the setpoints being charted
        self.s: float | None = None  # located arc length of that job (path units)
        self.position: list[float] | None = None
        self.finished: dict[str, dict] = {}  # job -> its job_finished event
        self.report: dict | None = None
        self.report_id = 0
        self.batches = 0
        self.bad_messages = 0
        self.commands: deque[dict] = deque(maxlen=50)
        #: messages waiting in the monitor's own queue (set by the bus side)
        self.backlog = 0

    # --- from the bus ---------------------------------------------------------------------
    def on_alive(self, who: str, alive: bool) -> None:
        with self.lock:
            setattr(self, f"{who}_alive", alive)

    def on_status(self, status: Status) -> None:
        with self.lock:
            self.status = asdict(status)
            self.status_t = time.monotonic()

    def on_event(self, event: Event) -> None:
        with self.lock:
            extra = {k: v for k, v in event.extra.items()
                     if isinstance(v, str | int | float | bool) or v is None}
            self.events.append({"id": self.event_id, "wall": time.time(), "type": event.type,
                                "job": event.job, "k": event.k, **extra})
            self.event_id += 1
            if event.type == "job_finished" and event.job is not None:
                self.finished[event.job] = {"k": event.k, **extra}
                if event.job == self.job:
                    self.chart.close()

    def on_segment(self, seg: Segment) -> None:
        with self.lock:
            path = self.paths.get(seg.job)
            if path is None:
                path = self.paths[seg.job] = ProgrammedPath(seg.job, self.spec.path_scale)
                while len(self.paths) > PATHS_KEPT:
                    self.paths.pop(next(iter(self.paths)))
            path.add(seg)

    def on_setpoints(self, batches: list[SetpointBatch]) -> None:
        """Consecutive batches of one job (contiguous sample indices), in order."""
        with self.lock:
            self.batches += len(batches)
            if any(b.axes != self.spec.axes for b in batches):
                self.bad_messages += 1
                return
            first = batches[0]
            pos = np.vstack([b.pos for b in batches])
            if pos.shape[0] == 0:
                return
            if first.job != self.job:
                self.chart.close()
                self.chart.reset()
                self.job = first.job
                self.s = None
            self.chart.add(first.k0, pos)
            path = self.paths.get(first.job)
            if path is not None:
                for i in range((-first.k0) % LOCATE_EVERY, pos.shape[0], LOCATE_EVERY):
                    self.s = path.locate(pos[i])
                self.s = path.locate(pos[-1])
            self.position = pos[-1].tolist()
            if batches[-1].final:
                self.chart.close()

    def on_report(self, report: dict) -> None:
        with self.lock:
            self.report = _finite(report)
            self.report_id += 1

    def on_bad(self) -> None:
        with self.lock:
            self.bad_messages += 1

    def on_command(self, verb: str, value: float | None, reply: dict) -> None:
        with self.lock:
            self.commands.append({"wall": time.time(), "verb": verb, "value": value, **reply})

    # --- for the web side -----------------------------------------------------------------
    def service(self) -> str:
        """'up' (the planner's token is there), 'none' (no token since the monitor started
        watching, NO_SERVICE_AFTER_S ago) or 'checking'."""
        if self.planner_alive:
            return "up"
        if self.planner_alive is False or \
                time.monotonic() - self.started > NO_SERVICE_AFTER_S:
            return "none"
        return "checking"

    def snapshot(self, chart_cursor: int = 0, event_cursor: int = 0,
                 path_version: tuple[str | None, int] | None = None) -> dict:
        """Everything the page shows; rows and events from the cursors on, the path only if
        its (job, version) differs from `path_version`."""
        with self.lock:
            job = self.job
            status = self.status
            if status is not None and status.get("job") and status["job"] != job \
                    and status["job"] in self.paths:
                job = status["job"]  # a job whose setpoints have not come yet
            path = self.paths.get(job) if job is not None else None
            progress = self._progress(job, path)
            rows = [r.to_json() for r in self.chart.since(chart_cursor)]
            events = [e for e in self.events if e["id"] >= event_cursor]
            out = {
                "id": self.spec.id, "ns": self.spec.ns, "service": self.service(),
                "planner_alive": self.planner_alive, "machine_alive": self.machine_alive,
                "status": status,
                "status_age_s": None if status is None else time.monotonic() - self.status_t,
                "job": job, "progress": progress, "position": self.position,
                "rows": rows, "next_row": self.chart.next_id,
                "events": events, "next_event": self.event_id,
                "peak": {"v": self.chart.peak[0].tolist(), "a": self.chart.peak[1].tolist(),
                         "j": self.chart.peak[2].tolist()},
                "samples": self.chart.samples, "gaps": self.chart.gaps,
                "batches": self.batches, "bad_messages": self.bad_messages,
                "backlog": self.backlog,
                "report": self.report, "report_id": self.report_id,
                "commands": list(self.commands)[-5:],
            }
            if path is not None and (job, path.version) != path_version:
                out["path"] = {"job": job, "version": path.version, "points": path.drawing(),
                               "segments": path.segments, "complete": path.complete}
            return out

    def _progress(self, job: str | None, path: ProgrammedPath | None) -> dict:
        """Progress fields with what they are based on (module docstring)."""
        status = self.status or {}
        same = status.get("job") == job and job is not None
        out: dict = {
            "elapsed_s": status.get("k", 0) * self.spec.dt if same else None,
            "planned_ahead_s": status.get("horizon_s") if same else None,
            "remaining_s": (status.get("remaining_s") if same and status.get("plan_complete")
                            else None),
            "duration_s": None, "fraction": None, "basis": None,
        }
        if job is None:
            return out
        done = self.finished.get(job)
        if done is not None:
            out["duration_s"] = done.get("duration_s")
            if done.get("aborted"):
                out["basis"] = "aborted"
        if path is None:
            out["basis"] = out["basis"] or "the monitor did not see this job's segments"
        elif not path.complete:
            out["basis"] = (f"{path.segments} segments seen, the path is not complete "
                            "(the monitor joined late or segments are still coming)")
        else:
            frac = path.progress(self.s if job == self.job else 0.0)
            out["fraction"] = frac
            out["basis"] = out["basis"] or (
                f"commanded position along the programmed path ({path.segments} "
                f"segment{'' if path.segments == 1 else 's'}, {path.length:.1f} path units)")
        return out


def _finite(obj):
    """`obj` (plain msgpack data) with non-finite floats as None (JSON has no inf/nan) and
    bytes as their length (a report carries none, a foreign machine might)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, bytes):
        return f"<{len(obj)} bytes>"
    return obj
