"""The monitor's bus side: one zenoh session, subscriptions for every watched machine, and
the commands the page sends (imports zenoh).

It only subscribes and queries: it declares no publisher and no queryable, so the service
does nothing for it beyond delivering samples. Subscribers use a RingChannel: if the monitor
falls behind, the oldest samples are dropped on ITS side (counted as chart gaps) instead of
pushing back on the service's blocking publishers. One thread decodes the samples into the
`MachineView`s; browsers never touch the session except to send a command.
"""

from __future__ import annotations

import logging
import queue
import threading
import time

import msgpack
import zenoh

from lookahead.protocol import (
    Command,
    CommandReply,
    Event,
    ProtocolError,
    Segment,
    SetpointBatch,
    Status,
    key,
)
from lookahead_clients.busio import close_session, drain, watch_liveliness
from lookahead_clients.monitor.machine_view import MachineView

log = logging.getLogger("lookahead.monitor")

#: samples a subscriber holds before the monitor drops the oldest (on its own side): several
#: seconds of 10-sample batches at 1 kHz, so only a monitor stalled that long loses any
RING_CAPACITY = 4096
#: suffixes of NS subscribed, and what they carry
TOPICS = ("status", "events", "setpoints", "segments", "machine/report")
#: the bus thread takes what arrived in this long at once (s): batches of 10 samples come
#: at 100 Hz in real time, so a pass handles ~2 (~6 % of a loaded core, measured on
#: tube-9570 positions; 1 batch a pass costs twice that),
#: and a backlog (a --fast run) is taken in passes of up to MAX_PASS messages
COALESCE_S = 0.02
MAX_PASS = 5000
#: how long a command waits for the service's reply (s)
COMMAND_TIMEOUT_S = 5.0


class MonitorBus:
    """Subscribes every view's NS; `command` sends one PROTOCOL.md command."""

    def __init__(self, session, views: dict[str, MachineView]) -> None:
        self.session = session
        self.views = views
        self.inbox: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._subs = []
        self._by_prefix: list[tuple[str, str, MachineView]] = []
        for view in views.values():
            ns = view.spec.ns
            for topic in TOPICS:
                sub = session.declare_subscriber(key(ns, topic),
                                                 zenoh.handlers.RingChannel(RING_CAPACITY))
                drain(sub, self.inbox, session=session)
                self._subs.append(sub)
                self._by_prefix.append((key(ns, topic), topic, view))
            for who in ("planner", "machine"):
                self._subs.append(watch_liveliness(session, key(ns, "alive", who), self.inbox))
                self._by_prefix.append((key(ns, "alive", who), f"alive/{who}", view))
        self._thread = threading.Thread(target=self._loop, daemon=True, name="monitor-bus")
        self._thread.start()
        threading.Thread(target=self._probe_liveliness, daemon=True,
                         name="monitor-alive").start()

    def _probe_liveliness(self) -> None:
        """Settle each planner token's state once (a subscriber with history reports only
        tokens that exist, so an absent one is learnt from a query)."""
        for view in self.views.values():
            for who in ("planner", "machine"):
                try:
                    replies = self.session.liveliness().get(
                        key(view.spec.ns, "alive", who), timeout=1.0)
                    present = any(r.ok is not None for r in replies)
                except zenoh.ZError:
                    return  # closing
                with view.lock:
                    current = getattr(view, f"{who}_alive")
                    if current is None or present:
                        setattr(view, f"{who}_alive", present)

    def _route(self, key_expr: str) -> tuple[str, MachineView] | None:
        for prefix, topic, view in self._by_prefix:
            if key_expr == prefix:
                return topic, view
        return None

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                items = [self.inbox.get(timeout=0.1)]
            except queue.Empty:
                continue
            time.sleep(COALESCE_S)  # let a few more arrive, then take them all at once
            while len(items) < MAX_PASS:
                try:
                    items.append(self.inbox.get_nowait())
                except queue.Empty:
                    break
            backlog = self.inbox.qsize()
            for view in self.views.values():
                view.backlog = backlog
            self._pass(items)

    def _pass(self, items: list) -> None:
        """Handle `items` in order; consecutive setpoint batches of one job go to their
        view together (one finite-difference pass over all of them)."""
        run: list[SetpointBatch] = []
        run_view: MachineView | None = None

        def flush() -> None:
            if run and run_view is not None:
                run_view.on_setpoints(list(run))
            run.clear()

        for item in items:
            routed = self._route(item.key)
            if routed is None:
                continue
            topic, view = routed
            if item.kind in ("alive", "gone"):
                flush()
                view.on_alive(topic.split("/", 1)[1], item.kind == "alive")
                continue
            if item.kind != "put":
                continue
            try:
                if topic == "setpoints":
                    batch = SetpointBatch.decode(item.payload)
                    if run and (view is not run_view or batch.job != run[-1].job
                                or batch.k0 != run[-1].k0 + run[-1].n):
                        flush()
                    run_view = view
                    run.append(batch)
                    continue
                flush()
                self._handle(topic, view, item.payload)
            except (ProtocolError, ValueError, TypeError) as exc:
                view.on_bad()
                log.warning("%s/%s: bad message ignored: %s", view.spec.ns, topic, exc)
        flush()

    @staticmethod
    def _handle(topic: str, view: MachineView, payload: bytes) -> None:
        if topic == "status":
            view.on_status(Status.decode(payload))
        elif topic == "events":
            view.on_event(Event.decode(payload))
        elif topic == "segments":
            view.on_segment(Segment.decode(payload, view.spec.axes))
        elif topic == "machine/report":
            report = msgpack.unpackb(payload, raw=False)
            if not isinstance(report, dict):
                raise ValueError("the machine report is not a map")
            view.on_report(report)

    def command(self, machine: str, verb: str, value: float | None) -> dict:
        """Send `verb` (with `value` for override) to `machine`'s service; returns
        {"ok": bool, "error": str | None, "by": "service" | "monitor"}: a value the protocol
        refuses is refused here before sending, as `lookahead cmd` does."""
        view = self.views[machine]
        try:
            payload = Command(verb, value).encode()
            Command.decode(verb, payload)
        except ProtocolError as exc:
            reply = {"ok": False, "error": str(exc), "by": "monitor"}
            view.on_command(verb, value, reply)
            return reply
        target = key(view.spec.ns, "cmd", verb)
        raw = None
        try:
            for answer in self.session.get(target, payload=payload, timeout=COMMAND_TIMEOUT_S):
                if answer.ok is not None:
                    raw = answer.ok.payload.to_bytes()
                    break
        except zenoh.ZError as exc:
            reply = {"ok": False, "error": f"bus error: {exc}", "by": "monitor"}
            view.on_command(verb, value, reply)
            return reply
        if raw is None:
            reply = {"ok": False, "by": "monitor",
                     "error": f"no service answered on {target} within {COMMAND_TIMEOUT_S:g} s"}
        else:
            try:
                decoded = CommandReply.decode(raw)
                reply = {"ok": decoded.ok, "error": decoded.error, "by": "service"}
            except ProtocolError as exc:
                reply = {"ok": False, "error": f"malformed reply: {exc}", "by": "monitor"}
        view.on_command(verb, value, reply)
        return reply

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        close_session(self.session)
